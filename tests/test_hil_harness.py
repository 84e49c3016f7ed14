"""tools/hil.py, the harness of `make hil`, without a kernel: where it runs the tests (this
machine's vcan0 first, User-Mode Linux otherwise, the reason where neither), and a kernel that
hangs killed on its time-out with nothing left running."""

from __future__ import annotations

import subprocess
import sys
import zlib
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import hil


def never(why: str):
    def probe() -> str | None:
        return why

    return probe


def fine() -> None:
    return None


def asked_not() -> str:
    raise AssertionError("probed, though not needed")


@pytest.mark.parametrize("where, native, uml, want", [
    ("auto", fine, asked_not, ("native", "")),
    ("auto", never("no vcan0"), fine, ("uml", "no vcan0")),
    ("auto", never("no vcan0"), never("no UML"), (None, "no vcan0; no UML")),
    ("native", fine, asked_not, ("native", "")),
    ("native", never("no vcan0"), asked_not,
     (None, "no vcan0; asked for this machine's vcan0")),
    ("uml", asked_not, fine, ("uml", "asked for User-Mode Linux")),
])  # fmt: skip
def test_the_harness_takes_a_native_vcan0_first_then_user_mode_linux(where, native, uml, want):
    assert hil.plan(where, native, uml) == want


def test_without_either_make_test_goes_on_and_make_hil_fails(monkeypatch, capsys):
    monkeypatch.setattr(hil, "native_vcan0", never("no vcan0 here"))
    monkeypatch.setattr(hil, "uml_ready", lambda install: "no User-Mode Linux")
    assert hil.main(["--if-possible"]) == 0
    assert hil.main([]) == 1
    err = capsys.readouterr().err
    assert err.count("hil: not run: no vcan0 here; no User-Mode Linux") == 2


def test_a_kernel_that_hangs_is_killed_with_all_it_started(tmp_path, monkeypatch, capsys):
    """A stand-in for linux.uml that never halts and starts a child of its own: after the
    time-out both are gone, and the harness reports no exit status (1)."""
    marker = f"sleep 3{zlib.crc32(str(tmp_path).encode()) % 10**6}.5"  # its own command line
    fake = tmp_path / "linux.uml"
    fake.write_text(f"#!/bin/sh\n{marker} &\n{marker}\n")
    fake.chmod(0o755)
    monkeypatch.setattr(hil, "UML", str(fake))
    assert hil.run_uml([], timeout=1.0, memory="64M") == 1
    err = capsys.readouterr().err
    assert "did not end in 1 s: killed" in err and "no exit status" in err
    left = subprocess.run(["pgrep", "-f", marker], capture_output=True, text=True).stdout
    assert left == ""
