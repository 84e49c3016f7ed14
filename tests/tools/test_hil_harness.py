"""tools/hil.py, the harness of `make hil`, without a kernel: where it runs the tests (this
machine's vcan0 first, User-Mode Linux otherwise, the reason where neither), and a kernel that
hangs killed on its time-out with nothing left running."""

from __future__ import annotations

import subprocess
import sys
import zlib
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
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


def test_a_kernel_that_cannot_start_init_here_is_not_run_and_said_so(tmp_path, monkeypatch,
                                                                     capsys):
    """A stand-in for linux.uml that ends as Debian's 6.1 kernel does on a CPU with AMX state:
    a panic before its init ran. ``make test`` goes on, saying why; ``make hil`` fails."""
    fake = tmp_path / "linux.uml"
    fake.write_text("#!/bin/sh\necho 'Run /tmp/x/init.sh as init process'\n"
                    "echo 'userspace - ptrace set fp regs failed, errno = 14'\n"
                    "echo 'Kernel panic - not syncing: Attempted to kill init!'\n")
    fake.chmod(0o755)
    monkeypatch.setattr(hil, "UML", str(fake))
    monkeypatch.setattr(hil, "native_vcan0", never("no vcan0 here"))
    monkeypatch.setattr(hil, "uml_ready", lambda install: None)
    assert hil.main(["--if-possible"]) == 0
    assert hil.main([]) == 1
    err = capsys.readouterr().err
    assert err.count("hil: not run: User-Mode Linux could not start a process on this machine "
                     "(its kernel said: 'userspace - ptrace set fp regs failed, errno = 14'); "
                     "the tests did not run") == 2


def synthetic_log(rate: float = 50.0, cycles: int = 300, change=None) -> str:
    """A `candump -L` log of a fault-free run as CiA 301/402 has it, written out here: each
    drive's boot-up, NMT pre-operational, an SDO exchange and a heartbeat per node, NMT start,
    then per cycle an RPDO per node, SYNC, a TPDO1 per node; heartbeats every 10 cycles.
    ``change(frames)`` edits the (time, id, hex data) list first."""
    nodes = range(1, 9)
    frames = [(0.0, 0x700 + n, "00") for n in nodes] + [(0.0005, 0x000, "8000")]
    for n in nodes:
        frames += [(0.001, 0x600 + n, "4000100000000000"), (0.002, 0x580 + n, "4300100092010200"),
                   (0.003, 0x700 + n, "7F")]  # fmt: skip
    frames.append((0.01, 0x000, "0100"))
    for k in range(cycles):
        t = 0.1 + k / rate
        frames += [(t, 0x200 + n, "0F000000") for n in nodes] + [(t + 1e-4, 0x080, "01")]
        frames += [(t + 2e-4, 0x180 + n, "37000000E8030000") for n in nodes]
        if k % 10 == 0:
            frames += [(t + 3e-4, 0x700 + n, "05") for n in nodes] + [(t + 3e-4, 0x77F, "05")]
    if change is not None:
        change(frames)
    return "".join(f"({t:.6f}) vcan0 {i:03X}#{d}\n" if i < 0x800 else
                   f"({t:.6f}) vcan0 {i:08X}#{d}\n" for t, i, d in sorted(frames))  # fmt: skip


def test_the_candump_witness_holds_a_right_log_and_fails_each_wrong_one():
    """The HIL demo's witness (tests/candump_witness.py) against logs written here: the right
    one passes; each departure from CiA 301/402 the witness claims to see fails it."""
    from candump_witness import check_candump

    check_candump(synthetic_log(), range(1, 9), 50.0)
    def without(pred):
        def change(frames: list) -> None:
            frames[:] = [x for x in frames if not pred(x)]

        return change

    def doubled_syncs(frames: list) -> None:
        frames += [(t + 0.01, i, "02") for t, i, _ in list(frames) if i == 0x080]

    wrong = {
        "a stray identifier": lambda f: f.append((1.0, 0x7E0, "")),
        "an EMCY": lambda f: f.append((2.0, 0x083, "1023010000000000")),
        "a second controller": lambda f: f.append((2.0, 0x77E, "05")),
        "NMT start first": lambda f: f.__setitem__(8, (0.0005, 0x000, "0100")),
        "no boot-up": without(lambda x: x[1] == 0x703 and x[2] == "00"),
        "a refused SDO": lambda f: f.append((0.004, 0x583, "8000100030000906")),
        "a node never heard": without(lambda x: x[1] == 0x705),
        "a node's TPDOs lost": without(lambda x: x[1] == 0x184 and x[0] > 4.0),
        "SYNC twice a cycle": doubled_syncs,
        "an error frame": lambda f: f.append((3.0, 0x20000080, "0000000000000000")),
        "a TPDO2": lambda f: f.append((3.0, 0x281, "00000000")),
    }
    for why, change in wrong.items():
        with pytest.raises(AssertionError):
            check_candump(synthetic_log(change=change), range(1, 9), 50.0)
            pytest.fail(f"the witness let {why} pass")


def test_a_terminated_harness_takes_its_kernel_and_all_it_started(tmp_path):
    """SIGTERM to tools/hil.py (a cancelled CI job) while its kernel runs: the kernel and what
    it started are killed, the harness ends at once with 130."""
    import signal
    import time

    marker = f"sleep 4{zlib.crc32(str(tmp_path).encode()) % 10**6}.5"
    fake = tmp_path / "linux.uml"
    fake.write_text(f"#!/bin/sh\n{marker} &\n{marker}\n")
    fake.chmod(0o755)
    code = (f"import sys; sys.path.insert(0, {str(Path(hil.__file__).parent)!r}); import hil; "
            f"hil.UML = {str(fake)!r}; sys.exit(hil.run_uml([], 300.0, '64M'))")  # fmt: skip
    proc = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not subprocess.run(
            ["pgrep", "-f", marker], capture_output=True).stdout:  # fmt: skip
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130 and "interrupted" in err, err
    assert subprocess.run(["pgrep", "-f", marker], capture_output=True, text=True).stdout == ""
