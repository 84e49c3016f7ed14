"""The robot's geometry: inverse and forward kinematics, the wrench matrix, the stiffness, the
cables' interference, the gripper's equations."""
