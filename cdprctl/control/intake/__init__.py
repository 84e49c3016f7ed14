"""Commands in: the desk (checked and planned outside the loop, handled in it) and the motion
sources it hands them to."""
