"""The compiled kernels' on-disk cache kept consistent with the sources.

numba keys a cached kernel by its own source file's stamp (modification time and size) only:
a kernel that calls a kernel of another module carries that callee's code in its cache entry,
and after an upgrade that changed the callee's module alone (``git pull`` touches the files it
changes) the caller would load its old code — ``interference_kernel`` (``geometry/
interference.py``) with an old ``box_box`` (``geometry/distance.py``), silently. So, before
any kernel loads: a digest of the stamps of every source file of the packages that hold
kernels; where it differs from the one recorded with the caches, every cache file of those
packages is removed (the kernels compile afresh, about a minute once) and the new digest
recorded. Stamps, not contents: ~300 ``stat`` calls, about a millisecond an import.

Where ``NUMBA_CACHE_DIR`` is set (``tools/mutation.py`` keeps a cache per mutant, removing the
mutated module's importers' entries itself) or the packages are not writable (an installed
copy: numba then caches per user), nothing is done.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: the packages beside each other that hold cached kernels
PACKAGES = ("cdprctl", "drivers", "sim_backend")
#: where the digest of the sources the caches were built from is kept
STAMP = Path("__pycache__") / "kernel-sources.digest"


def sources_digest(root: Path, packages: tuple[str, ...] = PACKAGES) -> str:
    """The digest of the (path, mtime ns, size) of every ``.py`` under ``root``'s ``packages``."""
    h = hashlib.sha256()
    for name in packages:
        for path in sorted((root / name).rglob("*.py")):
            st = path.stat()
            h.update(f"{path.relative_to(root)}:{st.st_mtime_ns}:{st.st_size}\n".encode())
    return h.hexdigest()


def fresh_kernel_caches(root: Path | None = None, packages: tuple[str, ...] = PACKAGES) -> int:
    """Remove the kernel caches of ``root``'s ``packages`` (default: where this package
    stands) if their sources changed since they were recorded; how many files were removed."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return 0
    root = Path(__file__).resolve().parents[2] if root is None else root
    stamp = root / packages[0] / STAMP
    if not os.access(stamp.parent if stamp.parent.exists() else root / packages[0], os.W_OK):
        return 0
    try:
        digest = sources_digest(root, packages)
        if stamp.exists() and stamp.read_text() == digest:
            return 0
        removed = 0
        for name in packages:
            for cache in (root / name).rglob("__pycache__/*.nb[ic]"):
                cache.unlink(missing_ok=True)
                removed += 1
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_suffix(f".{os.getpid()}")
        tmp.write_text(digest)
        tmp.replace(stamp)  # whole: a process starting beside this one reads one or the other
        return removed
    except OSError:  # a read-only or vanishing tree: numba's own keys are all there is
        return 0
