"""cdprctl: real-time controller daemon for cable-driven parallel robots."""

from cdprctl.core.kernel_cache import fresh_kernel_caches

__version__ = "0.1.0"

fresh_kernel_caches()  # before any kernel loads: stale caches go (core/kernel_cache.py)
