"""cdprctl: real-time controller daemon for cable-driven parallel robots."""

__version__ = "0.1.0"
