"""The CPUs' wake-up latency request (cdprctl/core/cpu_idle.py): what is written, for how
long it is held, and the warning where it cannot be made."""

from __future__ import annotations

import os
import struct
from pathlib import Path

from cdprctl.core.cpu_idle import CpuWakeupLatency


def open_on(path: Path) -> bool:
    """Whether this process holds a file descriptor on ``path``."""
    fds = Path("/proc/self/fd")
    return any(os.path.realpath(fds / fd) == str(path.resolve()) for fd in os.listdir(fds))


def test_the_latency_is_written_in_microseconds_and_held_until_released(tmp_path):
    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(b"")
    awake = CpuWakeupLatency(str(device))
    assert awake.hold(25e-6) == []
    assert struct.unpack("=i", device.read_bytes()) == (25,)  # the kernel reads a native int
    assert awake.held and open_on(device)
    assert awake.hold(0.0) == [] and device.read_bytes() == struct.pack("=i", 25)  # once
    awake.release()
    assert not awake.held and not open_on(device)
    awake.release()  # idempotent


def test_a_negative_latency_asks_for_nothing(tmp_path):
    device = tmp_path / "cpu_dma_latency"
    awake = CpuWakeupLatency(str(device))
    assert awake.hold(-1.0) == [] and not awake.held and not device.exists()


def test_a_refused_request_is_one_warning_naming_the_device_and_the_way_out(tmp_path):
    device = tmp_path / "absent" / "cpu_dma_latency"
    (warning,) = CpuWakeupLatency(str(device)).hold(0.0)
    assert f"0 µs not held ({device}: No such file or directory)" in warning
    assert "cpu_wakeup_latency = -1" in warning and "99-cdprctl.rules" in warning


def test_a_calibrations_cycles_hold_it_and_give_it_back_when_they_raise(tmp_path, monkeypatch):
    """``moves_held`` (the calibrations' cycles, real time asked): the request held in the
    body and released when the body raises (a drive fault's exception), as the daemon's loop
    does through the same ``realtime_loop``."""
    import dataclasses

    import pytest
    from conftest import CONFIG

    from cdprctl.commands.calibrating import moves_held
    from cdprctl.core import cpu_idle
    from cdprctl.core import realtime as rt
    from cdprctl.robot_file import load_robot

    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(b"")
    monkeypatch.setattr(cpu_idle, "PM_QOS_DEVICE", str(device))
    monkeypatch.setattr(rt, "schedule_realtime", lambda *a: [])  # the test's own thread stays
    model = load_robot(CONFIG / "rowc.toml")
    control = dataclasses.replace(model.control, freeze_gc=False, cpu_wakeup_latency=2e-6)
    model = dataclasses.replace(model, control=control)
    with pytest.raises(RuntimeError, match="a drive fault"), moves_held(model, True, print):
        assert open_on(device) and device.read_bytes() == struct.pack("=i", 2)
        raise RuntimeError("a drive fault")
    assert not open_on(device)
