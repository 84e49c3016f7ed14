"""The compiled kernels' on-disk cache, one per version of the sources.

numba keys a cached kernel by its own source file's stamp (modification time and size) only:
a kernel that calls a kernel of another module carries that callee's code in its cache entry,
and after an upgrade that changed the callee's module alone (``git pull`` touches the files it
changes) the caller would load its old code — ``interference_kernel`` (``geometry/
interference.py``) with an old ``box_box`` (``geometry/distance.py``), silently
(``tests/core/test_kernel_cache.py`` shows numba doing it). So, before any kernel loads, the
cache directory is chosen by a digest of the stamps of every source file of the packages
that hold kernels (``NUMBA_CACHE_DIR``, inherited by the processes this one starts): other
sources, another directory, compiled afresh (about a minute, once); a process still running
older sources keeps writing into its own. Nothing is deleted but directories of other digests
untouched for ``KEEP_DAYS``.

Where: ``.kernel-cache/<digest>`` beside the packages when that is writable (shared by the
tree's users and by User-Mode Linux's guest, which sees the tree), else
``$CACHE_DIRECTORY/kernels`` (systemd's ``CacheDirectory=``) or ``~/.cache/cdprctl/kernels``.
A ``NUMBA_CACHE_DIR`` already set (``tools/mutation.py``'s per-mutant caches) is kept.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

#: the packages beside each other that hold cached kernels
PACKAGES = ("cdprctl", "drivers", "sim_backend")
#: days a cache directory of other sources is kept after its last use
KEEP_DAYS = 7.0


def sources_digest(root: Path, packages: tuple[str, ...] = PACKAGES) -> str:
    """The digest of the (path, mtime ns, size) of every ``.py`` file under ``root``'s
    ``packages`` (an entry that cannot be read, say an editor's lock link, is left out)."""
    h = hashlib.sha256()
    for name in packages:
        for path in sorted((root / name).rglob("*.py")):
            try:
                st = path.stat()
            except OSError:
                continue
            h.update(f"{path.relative_to(root)}:{st.st_mtime_ns}:{st.st_size}\n".encode())
    return h.hexdigest()[:20]


def kernel_cache_dir(root: Path, packages: tuple[str, ...] = PACKAGES) -> Path | None:
    """The cache directory of the sources under ``root`` now (created), or None when none
    can be written (numba's own default then)."""
    digest = sources_digest(root, packages)
    bases = [root / ".kernel-cache"]
    if os.environ.get("CACHE_DIRECTORY"):  # systemd's CacheDirectory= (a service user's)
        bases.append(Path(os.environ["CACHE_DIRECTORY"].split(":")[0]) / "kernels")
    home = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    bases.append(Path(home) / "cdprctl" / "kernels")
    for base in bases:
        try:
            (base / digest).mkdir(parents=True, exist_ok=True)
            os.utime(base / digest)  # in use: not pruned
        except OSError:
            continue
        if os.access(base / digest, os.W_OK):
            _prune(base, digest)
            return base / digest
    return None


def _prune(base: Path, keep: str) -> None:
    """Remove the cache directories of other sources unused for ``KEEP_DAYS`` (best effort)."""
    old = time.time() - KEEP_DAYS * 86400.0
    for other in base.iterdir():
        try:
            if other.name != keep and other.is_dir() and other.stat().st_mtime < old:
                shutil.rmtree(other, ignore_errors=True)
        except OSError:
            continue


def choose_kernel_cache(root: Path | None = None, packages: tuple[str, ...] = PACKAGES) -> None:
    """``NUMBA_CACHE_DIR`` for the sources under ``root`` (default: where this package stands),
    unless one is set already; numba, if loaded already, told too."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    root = Path(__file__).resolve().parents[2] if root is None else root
    path = kernel_cache_dir(root, packages)
    if path is None:
        return
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    if "numba" in sys.modules:  # read when a kernel is cached, not only at numba's import
        from numba.core import config

        setattr(config, "CACHE_DIR", str(path))  # noqa: B010  (not in the stubs)
