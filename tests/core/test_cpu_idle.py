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
