"""Benchmark: the drivers' cyclic path and the simulator.

* driver cycle: encode + send 8 RPDOs + SYNC, drain + decode 8 TPDOs (the controller side of
  one cycle), on the in-process bus and on python-can's ``virtual`` bus;
* simulator: physics alone (8 cables, 5 kHz sub-steps), the simulated robot's side of a
  lock-step cycle (drive emulators + physics), and the whole lock-step cycle; as real-time
  factors and CPU seconds per simulated second.

Run: ``.venv/bin/python benchmarks/bench_drivers_sim.py``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line, row

from cdprctl.robot_file import load_robot
from sim_backend.network import LockStep
from sim_backend.plant import CdprPlant

CONFIG = Path(__file__).resolve().parents[1] / "config"


def driver_cycle(model, interface: str, n: int = 3000) -> list[np.ndarray]:
    ls = LockStep(model)
    if interface != "inprocess":  # reopen both ends on python-can's virtual bus
        ls.close()
        import sim_backend.network as nw

        chans = [f"bench-virtual-{b}" for b in range(len(model.drives.buses))]
        ov = {"interface": "virtual", "channels": chans}
        ls = LockStep.__new__(LockStep)
        ls.model, ls.period = model, 0.002
        ls.plant = CdprPlant(model)
        ls.net = nw.SimNetwork(model, ls.plant, ov)
        from drivers import create_driver

        ls.driver = create_driver(
            model, period=0.002, clock=ls.clock, wait=ls.net.advance, bus_overrides=ov
        )
    d = ls.driver
    d.configure()
    d.activate()
    tau = ls.plant.drum_ratio * ls.plant.tension
    samples = np.empty(n)
    for i in range(n):
        t = ls.net.time
        t0 = time.perf_counter_ns()
        d.read(t)
        d.write(t, tau)
        samples[i] = time.perf_counter_ns() - t0
        ls.net.advance(ls.period)
    ls.close()
    us = samples / 1000.0
    return [us[k::5] for k in range(5)]


def sim_rates(model) -> None:
    plant = CdprPlant(model)
    plant.step(0.01)  # compile
    sim_seconds = 5.0
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in range(round(sim_seconds / 0.002)):
        plant.step(0.002)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    print(
        f"  physics alone (5 kHz sub-steps): real-time factor {sim_seconds / wall:7.1f}x, "
        f"{cpu / sim_seconds * 1000:6.1f} ms CPU per simulated s"
    )
    with LockStep(model) as ls:
        ls.driver.configure()
        ls.driver.activate()
        tau = ls.plant.drum_ratio * ls.plant.tension
        n = round(sim_seconds / ls.period)
        sim_cpu = 0.0
        c0, w0 = time.process_time(), time.perf_counter()
        for _ in range(n):
            t = ls.net.time
            ls.driver.read(t)
            ls.driver.write(t, tau)
            s0 = time.process_time()
            ls.net.advance(ls.period)
            sim_cpu += time.process_time() - s0
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    print(
        f"  simulated robot side (8 drive emulators + physics): real-time factor "
        f"{sim_seconds / sim_cpu:7.1f}x, {sim_cpu / sim_seconds * 1000:6.1f} ms CPU per "
        "simulated s"
    )
    print(
        f"  whole lock-step cycle (driver + simulated robot): real-time factor "
        f"{sim_seconds / wall:7.1f}x, {cpu / sim_seconds * 1000:6.1f} ms CPU per simulated s"
    )


def main() -> None:
    import logging

    logging.getLogger("cdprctl.drivers").setLevel(logging.ERROR)  # the 95 % bus-load warning
    print(machine_line())
    for name in ("rowc", "seed000"):
        model = load_robot(CONFIG / f"{name}.toml")
        print(f"\n== {name}: {model.n_cables} {model.drives.driver} drives")
        print(row("driver cycle, in-process bus", driver_cycle(model, "inprocess")))
        print(row("driver cycle, python-can virtual bus", driver_cycle(model, "virtual")))
        sim_rates(model)


if __name__ == "__main__":
    main()
