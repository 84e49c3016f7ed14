"""The control cycle takes nothing from the allocator once warmed up (issue 64).

A block taken per cycle wakes the garbage collector and touches fresh pages: stalls of a
real-time loop. Lock-step against the simulated robot, enabled and mid-move, each case runs
CYCLES cycles with the controller's step alone measured (``alloc_probe.Window``: the driver's
read and write, the controller's update; not the simulated robot's step, and not the medium's
frames, which the window takes off the bus before it: a python-can bus builds a Message per
frame it receives, a medium's, not ours): per cycle, the bytes still held at its end and the
most held within it (a temporary taken and given back shows there), against its start. Then
CYCLES more: no site of cdprctl/ or drivers/ holds more than after the first CYCLES (the
snapshot's per-line statistics name any that does).

The claim is exact. Holding, our code takes no block at all. Moving, the one block a cycle
takes is ruckig's: its binding (nanobind) returns each of ``OutputParameter.new_position``,
``new_velocity``, ``new_acceleration`` as a new list, read one at a time and given back at
once (``motion/trajectory.py``), so the most held within a cycle is one such list's bytes,
measured here on the binding itself. Its input takes lists without a block, ``update`` and
``pass_to_input`` none.
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
from ruckig import OutputParameter

from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.robot_file import load_robot

CYCLES = 400  # the slowest growth found (+26 blocks per 1000 cycles) still shows in 400
# (each case's move lasts beyond 50 + CYCLES cycles: its end is an event, a block)
# frames kept per allocation: enough to reach cdprctl/ or drivers/ from numpy's and numba's
# own (the filters look anywhere in the stack); each frame more costs every traced cycle
DEPTH = 10
SLACK = 2  # blocks a site may gain over CYCLES cycles: free-list reuse, not growth
# What still takes blocks within a cycle, in the energy TDA with a gripper ramping only: the
# grippers' sensing (index arrays: a temporary each), the grasp estimate's, the energy TDA's
# Python path (lists of the impositions, numpy temporaries, an options object per cycle while
# a gripper ramps: ``dataclasses.replace`` of new ``Imposition``s).
REMAINING = {
    "grippers-energy": "the gripper sensing, the grasp estimate and the energy TDA's Python "
    "path take blocks (given back) while a gripper ramps: see the comment above",
}
# Slow growths found by this test, kept as expected failures, strictly, until they go: none
# now (the ODrive's feed-forward ints, +26 blocks in 1000 cycles, and the gripper planner's
# other impositions rebuilt each cycle, +73, went with issue 64's work).
GROWS: dict[str, str] = {}


def _sotda(model):
    control = dataclasses.replace(model.control, tda_method="sotda", tda_nu=0.9)
    return dataclasses.replace(model, control=control)


def _energy(model):
    return dataclasses.replace(
        model, control=dataclasses.replace(model.control, tda_method="energy")
    )


# robot, how its configured distribution is changed, the move (m along x), a gripper ramping
CASES = {
    "rowc": ("rowc.toml", None, 0.9, False),
    "rowc-sotda": ("rowc.toml", _sotda, 0.9, False),
    "rowc-odrive": ("rowc_odrive.toml", None, 0.9, False),
    "cogiro": ("cogiro.toml", None, 0.5, False),
    "grippers-energy": ("seed000_grippers.toml", _energy, 0.3, True),
}


def _moving(name: str, move: bool = True) -> ClosedLoop:
    """The case's robot enabled, a move under way (and a gripper ramping), a few hundred
    cycles in; without ``move``, holding where it was enabled."""
    file, change, dx, grip = CASES[name]
    model = load_robot(CONFIG / file)
    model = change(model) if change is not None else model
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    cl.run(0.3, record=False)
    if not move:
        return cl
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


# A cycle may end holding less than it started (never more): an object the simulated robot
# made whose last reference goes in the cycle, or a tuple handed back to a full free list, is
# freed there (-54 B now and then, on main too). Such a free could hide a block taken after
# it from the peak in that one cycle, not in the hundreds without one: a block taken every
# cycle or every few shows.


@pytest.fixture(scope="module")
def ruckig_list() -> int:
    """Bytes one read of ruckig's output takes (a new list, given back at once)."""
    out = OutputParameter(6)
    return peak_bytes(lambda: out.new_position)


def test_the_control_cycle_takes_no_block_but_ruckigs(measured, ruckig_list, request):
    """Moving, every cycle gives back all it takes, and the most it holds within it is one of
    ruckig's output lists (``ruckig_list`` bytes, measured on the binding): nothing of ours.
    (Frees, see above.)"""
    name, m = measured
    if name in REMAINING:
        request.applymarker(pytest.mark.xfail(strict=True, reason=REMAINING[name]))
    assert 0 < ruckig_list <= 64, ruckig_list  # a list of six floats' items
    assert (m.grew <= 0).all(), _why(name, m)  # frees: see above
    assert (m.peak <= ruckig_list).all(), _why(name, m)


@pytest.mark.parametrize("name", [n for n in CASES if n not in REMAINING])
def test_the_control_cycle_holding_takes_no_block(name):
    """Holding (ruckig not stepping), a cycle takes no block at all."""
    with _moving(name, move=False) as cl:
        tracemalloc.start(DEPTH)
        try:
            window = Window(cl)
            window.run(50)
            grew, peak = window.run(CYCLES // 4)
            assert cl.controller.data.state is State.ENABLED, cl.controller.data.fault_reason
            assert cl.controller.trajectory.finished
            sites = _temporaries(cl, window) if peak.any() or grew.any() else ""
        finally:
            tracemalloc.stop()
    assert not peak.any() and (grew <= 0).all(), (
        f"{name}: bytes held {np.unique(grew).tolist()}, most within a cycle "
        f"{np.unique(peak).tolist()}\n{sites}"
    )


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
    from cdprctl.core.numerics import largest, total, worst_ratio
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


def test_the_new_cycle_kernels_take_no_block():
    """The kernels that built arrays (numba's reference counting, a block per array argument
    and per array made) now take their scratch: the estimate with its forward kinematics
    (BLAS's 3×3 products into given arrays), the polygon TDAs (barycenter and SOTDA, the rate
    limit), the ODrive's frames and following error, the counters, the SYNC's sequence."""
    from cdprctl.control.cycle.estimator import Estimator
    from cdprctl.core.numerics import add_count, count_kernel
    from cdprctl.tda import TDAMethod, TDAOptions, TensionDistributor
    from cdprctl.tda.workspace import hold_wrench
    from drivers.cia402.sync_clock import sync_sent_kernel
    from drivers.odrive.cyclic import following_kernel, pack_frames_kernel

    model = load_robot(CONFIG / "rowc.toml")
    m, est = model.n_cables, Estimator(model)
    theta, tensions = np.zeros(m), np.full(m, 100.0)
    est.update(0.0, theta, tensions)
    hold = hold_wrench(model, model.home.rotation, np.zeros(6))
    tdas = {
        method: TensionDistributor(model, TDAOptions(method=method, max_tension_rate=1e4))
        for method in (TDAMethod.BARYCENTER, TDAMethod.SOTDA)
    }
    kin, t_prev = est.kin, np.full(m, 300.0)
    flags, f32 = np.ones(m, dtype=np.bool_), np.zeros(1, dtype=np.float32)
    frames = tuple(np.zeros(8, dtype=np.uint8) for _ in range(m))
    a, b, c = np.zeros(m), np.ones(m), np.full(m, 0.5)
    counts, instants = np.zeros(4, dtype=np.int64), np.zeros(8)
    latched, f32_bytes = np.zeros(m, dtype=np.bool_), f32.view(np.uint8)
    clock = [0.0]  # s: a float in a list (a float's block comes from its free list)

    def estimate() -> None:
        clock[0] += 0.001  # a later sample: the twist filtered too
        est.update(clock[0], theta, tensions)

    calls = {
        "Estimator.update": estimate,
        **{
            f"TensionDistributor.solve ({method.value})": (
                lambda tda=tda: tda.solve(kin.W, hold, k=est.k, kin=kin, t_prev=t_prev)
            )
            for method, tda in tdas.items()
        },
        "pack_frames_kernel": lambda: pack_frames_kernel(
            b, a, flags, 0.001, a, b, c, frames, f32, f32_bytes
        ),
        "following_kernel": lambda: following_kernel(
            flags, flags, a, b, c, a, c, a, latched, a, 0.001, 0.1
        ),
        "count_kernel": lambda: count_kernel(counts, 8),
        "add_count": lambda: add_count(counts, 1, 3),
        "sync_sent_kernel": lambda: sync_sent_kernel(counts, instants, 1.0),
    }
    for call in calls.values():  # warmed as the loop is: compiled, its bytecode specialised
        for _ in range(20):
            call()
    for name, tda in tdas.items():
        assert tda.out.status.name == "OK", (name, tda.out.message)
    taken = {name: peak_bytes(call, 3) for name, call in calls.items()}
    assert not any(taken.values()), taken
