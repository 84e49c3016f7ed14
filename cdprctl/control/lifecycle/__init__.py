"""The loop and the drives' I/O around the cycle: the manager, the fixed-rate loop, the warm-up, the
start-up's fixed point."""
