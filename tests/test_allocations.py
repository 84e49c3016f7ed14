"""The control cycle takes nothing from the allocator once warmed up (issue 64).

A block taken per cycle wakes the garbage collector and touches fresh pages: stalls of a
real-time loop. Lock-step against the simulated robot, enabled and mid-move, each case runs
CYCLES cycles with the controller's step alone measured (``alloc_probe.Window``: the driver's
read and write, the controller's update; not the simulated robot's step): per cycle, the
bytes still held at its end and the most held within it (a temporary taken and given back
shows there), against its start. Then CYCLES more: no site of cdprctl/ or drivers/ holds
more than after the first CYCLES (the snapshot's per-line statistics name any that does).
"""

from __future__ import annotations

import dataclasses
import gc
import logging
import tracemalloc

import numpy as np
import pytest
from alloc_probe import OURS, LineProbe, Window, peak_bytes
from conftest import CONFIG

from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.model import load_robot

CYCLES = 400  # the slowest growth found (+26 blocks per 1000 cycles) still shows in 400
# frames kept per allocation: enough to reach cdprctl/ or drivers/ from numpy's and numba's
# own (the filters look anywhere in the stack); each frame more costs every traced cycle
DEPTH = 10
SLACK = 2  # blocks a site may gain over CYCLES cycles: free-list reuse, not growth
# What still takes blocks within a cycle (each given back in it): the kernels that build
# arrays (the estimator's forward kinematics: np.eye and @; the planar TDA's) keep numba's
# reference counting, a block per array argument; ruckig's binding returns a new list per
# read and a new Result per update, and takes lists; python-can's frames are objects, read
# through a generator here; every Python ``for`` builds an iterator; counters past 256 build
# an int per increment; the ODrive frames are packed through Python ints; the energy TDA's
# options are rebuilt (dataclasses.replace) while a gripper ramps.
REMAINING = "the cycle still takes (and gives back) blocks: see the comment at the top"
# Slow growths found by this test, there on main too (blocks in 1000 cycles there): kept as
# expected failures, strictly, until they go.
GROWS = {
    # the gripper planner's impositions, a new options object each cycle (grippers.py _apply)
    "grippers-energy": "while a gripper ramps, its impositions' blocks accumulate (+73)",
    # the ints of the velocity feed-forward (odrive/driver.py _pack_position, round(rate))
    "rowc-odrive": "blocks of the ODrive's feed-forward ints accumulate (+26)",
}


def _sotda(model):
    control = dataclasses.replace(model.control, tda_method="sotda", tda_nu=0.9)
    return dataclasses.replace(model, control=control)


def _energy(model):
    return dataclasses.replace(
        model, control=dataclasses.replace(model.control, tda_method="energy")
    )


# robot, how its configured distribution is changed, the move (m along x), a gripper ramping
CASES = {
    "rowc": ("rowc.toml", None, 0.4, False),
    "rowc-sotda": ("rowc.toml", _sotda, 0.4, False),
    "rowc-odrive": ("rowc_odrive.toml", None, 0.4, False),
    "cogiro": ("cogiro.toml", None, 0.5, False),
    "grippers-energy": ("seed000_grippers.toml", _energy, 0.3, True),
}


def _moving(name: str) -> ClosedLoop:
    """The case's robot enabled, a move under way (and a gripper ramping), a few hundred
    cycles in."""
    file, change, dx, grip = CASES[name]
    model = load_robot(CONFIG / file)
    model = change(model) if change is not None else model
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    cl.run(0.3, record=False)
    goal = cl.controller.estimator.position.copy()
    goal[0] += dx
    cl.command("move", pose=np.concatenate([goal, model.home.rpy]))
    if grip:
        lo, hi = cl.controller.grippers.travel_range(1)
        cl.command("gripper", gripper=1, grip="travel", value=0.5 * (lo + hi))
    cl.run(0.4, record=False)
    return cl


def _sites(stats: list[tracemalloc.StatisticDiff]) -> str:
    return "\n".join(f"  {s}" for s in stats if s.size_diff or s.count_diff)


def _temporaries(cl: ClosedLoop, window: Window) -> str:
    """The lines taking blocks within a cycle (a line tracer: a rough guide, the tracing's
    own frames and locals make a few bytes of noise on any line calling Python code)."""
    probe = LineProbe()
    for _ in range(3):
        probe.step(cl, window.buses)
    return "\n".join(f"  {s}: {b // 3} B" for s, b in probe.sites.most_common(25) if b > 3 * 64)


@pytest.fixture(scope="module", autouse=True)
def _quiet():
    logging.getLogger("cdprctl.drivers").setLevel(logging.ERROR)


@dataclasses.dataclass
class Measured:
    grew: np.ndarray  # bytes held at the end of each of the first CYCLES, against its start
    peak: np.ndarray  # the most held within each of them, against its start
    held: np.ndarray  # as ``grew``, the next CYCLES (the first few may settle in)
    kept: list[tracemalloc.StatisticDiff]  # sites holding more after 2 x CYCLES than CYCLES
    temporaries: str  # the line tracer's sites, filled when a check fails


@pytest.fixture(scope="module", params=list(CASES))
def measured(request):
    name = request.param
    with _moving(name) as cl:
        tracemalloc.start(DEPTH)
        try:
            window = Window(cl)
            window.run(50)  # what the start of tracing stirs up settles
            grew, peak = window.run(CYCLES)
            gc.collect()  # kept, not garbage awaiting the collector
            first = tracemalloc.take_snapshot().filter_traces(_filters())
            held, _ = window.run(CYCLES)
            gc.collect()
            later = tracemalloc.take_snapshot().filter_traces(_filters())
            state = cl.controller.data.state
            assert state in (State.MOVING, State.ENABLED), cl.controller.data.fault_reason
            # a block or two may move between sites as the free lists are reused (a float
            # held by an attribute keeps the site of its first allocation): more is growth
            kept = [s for s in later.compare_to(first, "lineno") if s.count_diff > SLACK]
            found = peak.any() or kept
            sites = _temporaries(cl, window) if found else ""
            return name, Measured(grew, peak, held, kept, sites)
        finally:
            tracemalloc.stop()


def _why(name: str, m: Measured) -> str:
    return (
        f"{name}: per cycle, bytes held at its end {np.unique(m.grew).tolist()}, most held "
        f"within it {np.unique(m.peak).tolist()}\nheld more after {2 * CYCLES} cycles than "
        f"after {CYCLES}:\n{_sites(m.kept)}\ntaken within a cycle:\n{m.temporaries}"
    )


def test_the_control_cycle_keeps_nothing(measured, request):
    """Nothing accumulates: no site of cdprctl/ or drivers/ (anywhere in the allocation's
    stack) holds more after 2 x CYCLES cycles than after CYCLES, the collector run before each
    count."""
    name, m = measured
    if name in GROWS:  # as on main, where they were found
        request.applymarker(pytest.mark.xfail(strict=True, reason=GROWS[name]))
    assert not m.kept, _why(name, m)


@pytest.mark.xfail(strict=True, reason=REMAINING)
def test_the_control_cycle_takes_no_block(measured):
    name, m = measured
    assert not m.peak.any() and not m.grew.any(), _why(name, m)


def _filters() -> list[tracemalloc.Filter]:
    return [tracemalloc.Filter(True, f"{root}/*", all_frames=True) for root in OURS]


def test_a_planted_temporary_is_caught():
    """The probe is not blind: a temporary built in the cycle (the update wrapped; larger
    than what the cycle takes today, so that it shows above it) raises the peak, and a list
    kept per cycle shows in the bytes held and in the snapshot, at its line."""
    with _moving("rowc") as cl:
        update, kept = cl.controller.update, []

        def temporary(t, st):
            update(t, st)
            return [0.0] * 2000  # 16 kB, dropped at once

        def leaky(t, st):
            update(t, st)
            kept.append(bytearray(200))  # no free list to hide it (floats have one)

        tracemalloc.start(25)
        try:
            window = Window(cl)
            _, before = window.run(20)
            cl.controller.update = temporary
            _, peak = window.run(20)
            assert (peak > before.max() + 10_000).all()
            cl.controller.update = leaky
            first = tracemalloc.take_snapshot()
            grew, _ = window.run(20)
            later = tracemalloc.take_snapshot()
            assert grew.sum() > 20 * 100
            top = later.compare_to(first, "lineno")[0]
            assert top.count_diff >= 20 and top.traceback[0].filename == __file__
        finally:
            tracemalloc.stop()


def test_the_cycle_kernels_take_no_block():
    """A ``cycle_kernel`` passes its arrays as they are: a call from Python takes no block
    (with numba's reference counting each array argument took one)."""
    from cdprctl.numerics import largest, total, worst_ratio
    from cdprctl.tda.nullspace import NullSpace
    from drivers.base import clamp_kernel
    from drivers.cia402.cyclic import decode_tpdo1_kernel, pack_rpdo1_kernel

    rng = np.random.default_rng(0)
    W, w, v, lim = rng.normal(size=(6, 8)), rng.normal(size=6), rng.normal(size=8), np.ones(8)
    ns, out = NullSpace(8), np.zeros(8)
    fields, counts, position = np.ones((8, 2), dtype=np.int64), np.ones(8, dtype=np.int64), lim > 0
    frames = tuple(np.zeros(8, dtype=np.uint8) for _ in range(8))
    raw, rows = np.zeros((8, 8), dtype=np.uint8), np.zeros((8, 4), dtype=np.int64)
    calls = {
        "total": lambda: total(v),
        "largest": lambda: largest(v),
        "worst_ratio": lambda: worst_ratio(v, lim),
        "clamp_kernel": lambda: clamp_kernel(v, out, lim, out),
        "NullSpace.update": lambda: ns.update(W, w),
        "NullSpace.particular": lambda: ns.particular(w, out),
        "pack_rpdo1_kernel": lambda: pack_rpdo1_kernel(fields, counts, position, frames),
        "decode_tpdo1_kernel": lambda: decode_tpdo1_kernel(8, raw, counts, rows),
    }
    taken = {name: peak_bytes(call) for name, call in calls.items()}
    assert not any(taken.values()), taken
