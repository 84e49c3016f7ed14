"""cdprctl: real-time controller daemon for cable-driven parallel robots."""

from cdprctl.core.kernel_cache import choose_kernel_cache

__version__ = "0.1.0"

choose_kernel_cache()  # before any kernel is compiled: a cache per version of the sources
