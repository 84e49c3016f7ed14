"""The control loop: estimation, trajectory, PD + feedforward, TDA, winch torques, supervisor."""
