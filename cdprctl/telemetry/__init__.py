"""The processes beside the loop's (Zenoh, Foxglove, ROS 2), fed by its shared-memory snapshot; a
run recorded (MCAP) and reported."""
