"""The controller against the simulated robot in lock-step: the closed-loop harness, the
reliability matrix's scenarios and the gripper experiments. Above both the control layer and
``sim_backend`` (which imports neither this nor the controller)."""
