"""What the CiA 402 set-up (drivers/cia402/drive_setup.py) writes into each drive, read back
from the simulated drives' object dictionaries and checked against the config by hand: the
producer heartbeat (five per [drives] heartbeat_timeout), the following-error window (m of
cable through the drum, in encoder counts) and time-out (ms), the maximum torque (per mille of
the rated torque), the mode."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from cdprctl.robot_file import load_robot
from sim_backend.network import LockStep

CONFIG = Path(__file__).resolve().parents[3] / "config"


@pytest.mark.parametrize(("heartbeat", "fe_timeout", "window"),
                         [(0.5, 0.003, None), (2.51, 0.6, 0.002), (1.7, 0.0004, 0.0005)])
def test_the_set_up_writes_the_configs_values_into_each_drive(heartbeat, fe_timeout, window):
    model = load_robot(CONFIG / "rowc.toml")
    drives = dataclasses.replace(model.drives, heartbeat_timeout=heartbeat,
                                 following_error_timeout=fe_timeout,
                                 following_error_window=window)  # fmt: skip
    model = dataclasses.replace(model, drives=drives)
    with LockStep(model, period=0.004) as ls:
        ls.driver.configure()
        for i, c in enumerate(model.cables):
            od = ls.net.drives[i].od
            w = c.winch
            assert od[(0x1017, 0)] == max(1, round(heartbeat * 1000 / 5)), i  # ms
            assert od[(0x6066, 0)] == max(1, round(fe_timeout * 1000)), i  # ms
            rad = (window * w.gear_ratio / w.drum_radius if window is not None
                   else drives.following_error_window_rad(w))  # fmt: skip
            counts = round(rad / (2 * math.pi) * w.encoder_counts_per_rev)
            assert od[(0x6065, 0)] == max(1, counts), i
            assert od[(0x6072, 0)] == round(w.torque_limit / drives.rated_torque * 1000), i
            assert od[(0x6060, 0)] == 8  # cyclic synchronous position
