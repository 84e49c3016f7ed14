"""`cdprctl record --mcap`: a recording as MCAP, with its ROS 2 channels."""
