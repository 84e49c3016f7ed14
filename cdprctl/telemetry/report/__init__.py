"""A recording read back and `cdprctl report`'s figures."""
