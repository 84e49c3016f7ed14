"""The kernels' cache kept with the sources (``cdprctl/core/kernel_cache.py``): numba itself
loads a caller's stale code after only its callee's module changed (shown here, in processes
of their own, as an upgrade would), and ``fresh_kernel_caches`` removes the caches then, and
only then."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from cdprctl.core.kernel_cache import fresh_kernel_caches

CALLEE = "from numba import njit\n\n@njit(cache=True)\ndef f():\n    return {value}\n"
CALLER = ("from pk.callee import f\nfrom numba import njit\n\n@njit(cache=True)\n"
          "def g():\n    return f()\n")


def _tree(root: Path, value: int) -> None:
    (root / "pk").mkdir(exist_ok=True)
    (root / "pk" / "__init__.py").write_text("")
    (root / "pk" / "callee.py").write_text(CALLEE.format(value=value))
    if not (root / "pk" / "caller.py").exists():
        (root / "pk" / "caller.py").write_text(CALLER)


def _run(root: Path, fresh: bool) -> str:
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(root)!r})
        from pathlib import Path
        from cdprctl.core.kernel_cache import fresh_kernel_caches
        if {fresh}:
            fresh_kernel_caches(Path({str(root)!r}), ("pk",))
        from pk.caller import g
        print(g())
    """)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def _upgrade(root: Path, value: int) -> None:
    """The callee's module changed, as ``git pull`` changes it: a new content, a new mtime."""
    _tree(root, value)
    st = (root / "pk" / "callee.py").stat()
    os.utime(root / "pk" / "callee.py", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))


def test_numba_alone_runs_a_callers_stale_code_and_the_check_does_not(tmp_path):
    stale, fresh = tmp_path / "stale", tmp_path / "fresh"
    for root, check in ((stale, False), (fresh, True)):
        root.mkdir()
        _tree(root, 1)
        assert _run(root, check) == "1"  # compiled and cached
        _upgrade(root, 2)
    assert _run(stale, False) == "1"  # numba's own keys: the caller's old code, callee and all
    assert _run(fresh, True) == "2"


def test_the_caches_go_only_when_a_source_changed(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    _tree(tmp_path, 1)
    cache = tmp_path / "pk" / "__pycache__"
    cache.mkdir()
    (cache / "caller.g-4.py311.nbi").write_text("")
    (cache / "caller.g-4.py311.1.nbc").write_text("")
    assert fresh_kernel_caches(tmp_path, ("pk",)) == 2  # no digest recorded yet
    (cache / "caller.g-4.py311.nbi").write_text("")
    assert fresh_kernel_caches(tmp_path, ("pk",)) == 0  # the same sources: kept
    assert (cache / "caller.g-4.py311.nbi").exists()
    _upgrade(tmp_path, 2)
    assert fresh_kernel_caches(tmp_path, ("pk",)) == 1
    assert not (cache / "caller.g-4.py311.nbi").exists()
    _upgrade(tmp_path, 3)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))  # its owner's to keep
    (cache / "caller.g-4.py311.nbi").write_text("")
    assert fresh_kernel_caches(tmp_path, ("pk",)) == 0
    assert (cache / "caller.g-4.py311.nbi").exists()
