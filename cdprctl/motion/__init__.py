"""Motion planning below the control loop: the jerk-limited trajectory (ruckig), path files
(CSV, G-code) and their checked plans, and the soft limits of a jog."""
