"""The kernels' cache, one per version of the sources (``cdprctl/core/kernel_cache.py``):
numba alone loads a caller's stale code after only its callee's module changed (shown here in
processes of their own, as after an upgrade: an upstream limitation this works around), and
with the cache chosen by the sources' digest the caller is compiled afresh."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cdprctl.core import kernel_cache
from cdprctl.core.kernel_cache import choose_kernel_cache, kernel_cache_dir

CALLEE = "from numba import njit\n\n@njit(cache=True)\ndef f():\n    return {value}\n"
CALLER = ("from pk.callee import f\nfrom numba import njit\n\n@njit(cache=True)\n"
          "def g():\n    return f()\n")  # fmt: skip


def _tree(root: Path, value: int) -> None:
    (root / "pk").mkdir(exist_ok=True)
    (root / "pk" / "__init__.py").write_text("")
    (root / "pk" / "callee.py").write_text(CALLEE.format(value=value))
    if not (root / "pk" / "caller.py").exists():
        (root / "pk" / "caller.py").write_text(CALLER)


def _run(root: Path, chosen: bool) -> str:
    """``pk.caller.g()`` in a process of its own: numba's cache beside the sources, or the
    one ``choose_kernel_cache`` picks for them."""
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(root)!r})
        from pathlib import Path
        import os
        from cdprctl.core.kernel_cache import choose_kernel_cache
        os.environ.pop("NUMBA_CACHE_DIR", None)  # cdprctl's own, for its sources: not pk's
        if {chosen}:
            choose_kernel_cache(Path({str(root)!r}), ("pk",))
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


def test_numba_alone_runs_a_callers_stale_code_and_a_cache_per_version_does_not(tmp_path):
    stale, fresh = tmp_path / "stale", tmp_path / "fresh"
    for root, chosen in ((stale, False), (fresh, True)):
        root.mkdir()
        _tree(root, 1)
        assert _run(root, chosen) == "1"  # compiled and cached
        _upgrade(root, 2)
    # numba's own keys (upstream): the caller's old code, its old callee inlined
    assert _run(stale, False) == "1"
    assert _run(fresh, True) == "2"
    assert len(list((fresh / ".kernel-cache").iterdir())) == 2  # one per version


def test_the_directory_follows_the_sources_and_a_set_one_is_kept(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    _tree(tmp_path, 1)
    first = kernel_cache_dir(tmp_path, ("pk",))
    assert first is not None and first.parent == tmp_path / ".kernel-cache" and first.is_dir()
    assert kernel_cache_dir(tmp_path, ("pk",)) == first  # the same sources: the same
    _upgrade(tmp_path, 2)
    second = kernel_cache_dir(tmp_path, ("pk",))
    assert second != first and first.is_dir()  # the old one kept for a process still on it
    os.utime(first, (0, 0))  # unused for longer than KEEP_DAYS: pruned by the next choice
    kernel_cache_dir(tmp_path, ("pk",))
    assert not first.exists() and second.is_dir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))  # its owner's
    choose_kernel_cache(tmp_path, ("pk",))
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "elsewhere")


def test_an_unwritable_tree_falls_back_to_the_users_cache(tmp_path, monkeypatch):
    """The service's user cannot write the installed tree: systemd's CacheDirectory= (or the
    user's ~/.cache) takes the caches, keyed the same way; an unreadable entry (an editor's
    lock link) does not stop the digest."""
    _tree(tmp_path, 1)
    (tmp_path / "pk" / ".#callee.py").symlink_to(tmp_path / "nowhere")  # a broken link
    blocked = tmp_path / ".kernel-cache"
    blocked.write_text("")  # a file where the directory would go: not writable as one
    monkeypatch.setenv("CACHE_DIRECTORY", str(tmp_path / "var-cache"))
    path = kernel_cache_dir(tmp_path, ("pk",))
    assert path is not None and path.parent == tmp_path / "var-cache" / "kernels"
    assert path.name == kernel_cache.sources_digest(tmp_path, ("pk",))


@pytest.mark.parametrize("package", ["cdprctl", "drivers", "sim_backend"])
def test_every_package_chooses_the_cache_before_its_kernels(package):
    """A process that starts from any of the packages (``python -m sim_backend.process``, the
    simulated robot's) has the cache chosen before a kernel is decorated (numba picks a
    kernel's cache directory then)."""
    code = (f"import {package}, os, numba.core.config as c; "
            "print(os.environ['NUMBA_CACHE_DIR'] == c.CACHE_DIR != '')")  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120)  # fmt: skip
    assert out.stdout.strip() == "True", out.stderr
