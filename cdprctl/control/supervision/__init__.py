"""The checks, the faults, the stop, and the one owner of the state."""
