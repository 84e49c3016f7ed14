"""The rules every layer shares, each written once: rotations, the cable law and the clamps, the
real-time settings, the state directory and its files."""
