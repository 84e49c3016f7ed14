"""The moves of ``cdprctl calibrate geometry`` (:mod:`geometry_procedure`): the motor angles
and tensions that put the platform at a pose (``motor_goals``), a straight move between two
poses interpolated every cycle (``move``), where a stopped move backs off to (``retreat_to``),
and the platform held while the start is identified (``held_while``)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from cdprctl.calibration.geometry_plan import GeometryOptions, move_duration
from cdprctl.calibration.session import Session, hold_tensions
from cdprctl.core.numerics import compliance_of, unstretched_lengths
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.model.robot import RobotModel

# of the moves' speed, a retreat's: it starts where a cable is near its lower stop, and at full
# speed the way back let one go slack (CoGiRo at 0.2 m/s: 4 of 10 seeds stopped so, every one
# on its way back from pose 11; at 0.4 of it, seed 3 went through, anchors within 0.11 mm)
RETREAT_SPEED = 0.4
# m (and rad, the pose's 6-vector): how far a retreat goes back the way it came, the whole
# way when shorter. The tension that stopped the move fell over its last stretch; going back
# the whole way made CoGiRo's seed 20 retreat 0.9 m twice (415 s of motion, 5 minutes allowed)
RETREAT_DISTANCE = 0.1



def retreat_to(here: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Where a stopped move backs off to: ``RETREAT_DISTANCE`` back towards ``origin`` (the
    pose it came from, which held), or ``origin`` when that is nearer."""
    way = float(np.linalg.norm(origin - here))
    return here + min(1.0, RETREAT_DISTANCE / max(way, 1e-12)) * (origin - here)


# s the platform is held after the start is identified in lock-step (below)
HOLD_AFTER_IDENTIFYING = 1.0


def held_while(ses: Session, task: Callable[[], np.ndarray]) -> np.ndarray:
    """``task()`` (picklable: a module-level function or a ``functools.partial`` of one)
    while the session holds the platform, cycle by cycle: the drives want their SYNC and
    targets every period (an idle bus left their velocity readings at 10³ rad/s and a
    following-error fault at the next move, across processes).

    On a simulated clock (lock-step: the driver's ``clock`` is not the wall's) nothing waits
    for it: ``task()`` runs here, then the platform is held ``HOLD_AFTER_IDENTIFYING``.
    Held for as long as it took (5-8 s of wall time here: 900-1100 blocks of 0.05 s), the
    same seed gave other samples from run to run and under load. In real time it runs in a
    process of its own (``core.child_compute``), started from a thread at the normal
    scheduler off the loop's CPU (``realtime.worker_thread``), which it inherits: computed in
    a thread of this process, it held the interpreter's lock the holder's cycles wait for."""
    import time

    if ses.driver.clock is not time.monotonic:
        out = task()
        ses.run(HOLD_AFTER_IDENTIFYING)
        return out
    import threading

    from cdprctl.core import realtime as rt
    from cdprctl.core.child_compute import compute_in_child

    results: list[np.ndarray] = []
    failed: list[BaseException] = []
    held_in_real_time = _fifo()
    loop_cpu = rt.loop_cpu(ses.model.control.cpu) if held_in_real_time else None

    def work() -> None:
        if held_in_real_time:  # what the child inherits: out of FIFO, off the loop's CPU
            rt.worker_thread(loop_cpu)
        try:
            results.append(compute_in_child(task))
        except BaseException as exc:  # re-raised in the caller's thread
            failed.append(exc)

    worker = threading.Thread(target=work, name="cdprctl-identify", daemon=True)
    worker.start()
    while worker.is_alive():
        ses.run(0.05)
    if failed:
        raise failed[0]
    return results[0]


def _fifo() -> bool:
    """Whether the calling thread runs at ``SCHED_FIFO`` (``calibrate geometry``'s cycles,
    unless ``--no-realtime``)."""
    import os

    try:
        return os.sched_getscheduler(0) == os.SCHED_FIFO
    except (OSError, AttributeError):
        return False


GoalOf = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # pose -> (rad, N) per cable


def motor_goals(model: RobotModel, theta_ref: np.ndarray, l0_ref: np.ndarray,
                ratio: np.ndarray) -> GoalOf:  # fmt: skip
    """``goal_of(x)``: the motor angles (rad) that give pose ``x``'s unstretched lengths under
    its planned tensions, from motor angles ``theta_ref`` where the unstretched lengths are
    ``l0_ref`` (m; ``ratio``: m of cable per motor rad), and those tensions (N). The cable law
    whole: over a metre of travel rowc's compliance changes by half, 1.3 mm of stretch, 40 N
    on its stiff cables."""
    kin = KinematicsData(model)
    law = compliance_of(model.cables)

    def goal_of(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = hold_tensions(model, kin, x)
        return theta_ref - (unstretched_lengths(law, kin.length, t) - l0_ref) / ratio, t

    return goal_of


def move(ses: Session, a: np.ndarray, b: np.ndarray, goal_of: GoalOf, opt: GeometryOptions,
         stop: bool = True, track: np.ndarray | None = None,
         each: Callable[[float], None] | None = None) -> tuple[float, float]:  # fmt: skip
    """From pose ``a`` to ``b`` in a straight line (a cosine time law at ``opt.speed``): the
    planned motor angles and tensions every 1 cm (or 0.01 rad), interpolated per cycle.
    Returns the fraction done (a tension near its limit stops it, unless ``stop`` is False:
    a retreat along a way it came, where only the session's hard limits stop it) and the
    seconds taken (a stopped move ends where it stopped: holding the rest of its time would
    only add to the motion's). ``track`` (6): where the plan has the platform, every cycle
    (a stopped calibration resumes from there). ``each(s)``: called every cycle with the
    fraction ``s`` of the way the plan has the platform at (the friction calibration's
    samples)."""
    a, b = a.copy(), b.copy()  # ``track`` may be either
    dist = float(np.linalg.norm(b - a))
    n = max(2, math.ceil(dist / 0.01) + 1)
    fr = np.linspace(0.0, 1.0, n)
    m = ses.model.n_cables
    G, T = np.zeros((n, m)), np.zeros((n, m))
    ready = [0]  # waypoints computed: as the ramp needs them, a few per cycle at most (all at
    # once, a metre's 100 took 20-35 ms without a SYNC, a third of the drives' comm_timeout)
    base0, tension0 = ses.base.copy(), ses.tension_goal.copy()

    def waypoint(j: int) -> None:
        while ready[0] <= j:
            k = ready[0]
            G[k], T[k] = goal_of(a + fr[k] * (b - a))
            if k == 0:
                offset_g, offset_t = base0 - G[0], tension0 - T[0]
                G_off[:], T_off[:] = offset_g, offset_t
            # from where the drives are (a stopped move, the real start): that offset fades
            # out along the move, as ``Session.move``'s ramp does
            G[k] += (1.0 - fr[k]) * G_off
            T[k] += (1.0 - fr[k]) * T_off
            ready[0] += 1

    G_off, T_off = np.zeros(m), np.zeros(m)
    waypoint(0)
    duration = move_duration(dist, opt)
    reached = [0.0]  # the fraction of the way
    ses.begin_move()

    def step(f: float) -> bool:
        if stop and ses.move_stops():  # the targets stay where they are; the run ends
            ses.pace = 0.0
            return True
        s = 0.5 - 0.5 * math.cos(math.pi * f)
        reached[0] = s
        if track is not None:
            track[:] = a + s * (b - a)
        ses.pace = math.sin(math.pi * f)
        x = s * (n - 1)
        i = min(int(x), n - 2)
        u = x - i
        waypoint(i + 1)
        ses.base[:] = G[i] + u * (G[i + 1] - G[i])
        ses.tension_goal[:] = T[i] + u * (T[i + 1] - T[i])
        if each is not None:
            each(s)
        return False

    took = ses.run(duration, step)
    ses.pace = 0.0
    return reached[0], took
