"""The ROS 2 link: a process that publishes ROS 2's messages over DDS."""
