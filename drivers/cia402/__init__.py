"""CANopen CiA 402 winch drives in cyclic synchronous torque mode."""
