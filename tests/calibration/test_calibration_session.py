"""The calibration's session (cdprctl/calibration/session.py) against hand-written references:
the tensions read with the winches' friction taken out, the torques sent as the torque law with
that friction, and the force cables' tension loop following a ramp that asks for a rate."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from cdprctl.calibration.session import Session
from cdprctl.robot_file import load_robot
from drivers.vocabulary import Lifecycle

CONFIG = Path(__file__).resolve().parents[2] / "config"


class _Driver:
    """Answers its states, records each cycle's torques; a clock that moves by its waits."""

    def __init__(self, m: int):
        self.period, self.now = 0.004, 0.0
        self.lifecycle, self.error = Lifecycle.ACTIVE, ""
        self.states = SimpleNamespace(torque=np.zeros(m), position=np.zeros(m),
                                      velocity=np.zeros(m))  # fmt: skip
        self.sent: list[np.ndarray] = []

    def clock(self) -> float:
        return self.now

    def read(self, now: float):
        return self.states

    def write(self, now: float, torques, targets=None) -> None:
        self.sent.append(np.array(torques))

    def wait(self, dt: float) -> None:
        self.now += dt


def _friction(model, w: np.ndarray) -> np.ndarray:
    """N·m: b θ̇ + τ_c tanh(θ̇ / 0.05 rad/s), from the robot file's winches (docs/control.md)."""
    b = np.array([c.winch.viscous_friction for c in model.cables])
    tc = np.array([c.winch.coulomb_friction for c in model.cables])
    return b * w + tc * np.tanh(w / 0.05)


@pytest.mark.parametrize("robot", ["rowc", "cogiro"])
def test_tensions_are_read_with_the_winches_friction_at_their_speed_taken_out(robot):
    model = load_robot(CONFIG / f"{robot}.toml")
    m = model.n_cables
    d = _Driver(m)
    ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
    ses.states = d.states
    rng = np.random.default_rng(7)
    t_true = rng.uniform(100.0, 400.0, m)
    d.states.velocity[:] = rng.uniform(-3.0, 3.0, m)  # rad/s: moving
    d.states.torque[:] = ses.ratio * t_true + _friction(model, d.states.velocity)
    assert ses.tensions() == pytest.approx(t_true, rel=1e-9)
    d.states.velocity[:] = 0.0  # at rest: the torque is the tension's alone
    d.states.torque[:] = ses.ratio * t_true
    assert ses.tensions() == pytest.approx(t_true, rel=1e-12)


def test_the_torques_sent_are_the_torque_law_with_the_friction_at_the_measured_speed():
    model = load_robot(CONFIG / "cogiro.toml")
    assert model.control.friction_compensation
    m = model.n_cables
    d = _Driver(m)
    ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
    goal = np.linspace(150.0, 500.0, m)
    ses.tension_goal[:] = goal
    d.states.velocity[:] = np.linspace(-2.0, 2.0, m)
    d.states.torque[:] = ses.ratio * goal + _friction(model, d.states.velocity)
    ses.run(2 * d.period)
    limit = np.array([c.winch.torque_limit for c in model.cables])
    expected = np.clip(ses.ratio * goal + _friction(model, d.states.velocity), -limit, limit)
    assert d.sent[-1] == pytest.approx(expected, rel=1e-12)


def _ramp_error(pace_on: bool) -> tuple[float, float]:
    """A force cable as a spring: tension = k r (target − rest), its rest angle moved by a
    cosine ramp of 0.2 rad over 4 s (the plan's geometry off: the cable needs that much more
    than planned), the goal tension constant. Returns the largest tension error (N) during
    the ramp and at its end after 1 s at rest."""
    model = load_robot(CONFIG / "cogiro.toml")
    m = model.n_cables
    d = _Driver(m)
    ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
    ses.states = d.states
    ses.force[0] = True
    ses.k[:] = 2.0e5  # N/m
    ses.gain = 1.0 - math.exp(-2.0 * math.pi * 2.0 * d.period)  # 2 Hz, as the procedures
    ses.tension_goal[0] = 300.0
    kr = ses.k[0] * ses.ratio[0]  # N/rad
    rest0 = ses.correction[0] - 300.0 / kr  # the goal held at the start
    n, worst = 1000, 0.0
    ses.begin_move()
    for i in range(n + 250):
        f = min(1.0, (i + 1) / n)
        ses.pace = math.sin(math.pi * f) if (pace_on and i < n) else 0.0
        rest = rest0 + 0.2 * (0.5 - 0.5 * math.cos(math.pi * f))
        d.states.torque[0] = kr * (ses.correction[0] - rest) * ses.ratio[0]
        ses._tension_loop()
        if i < n:
            worst = max(worst, abs(300.0 - ses.tensions()[0]))
    return worst, abs(300.0 - ses.tensions()[0])


def test_the_tension_loop_learns_a_ramps_rate_and_is_the_plain_loop_at_rest():
    plain, plain_end = _ramp_error(False)
    learnt, learnt_end = _ramp_error(True)
    assert learnt < 0.5 * plain, (plain, learnt)  # the learnt rate halves the lag at least
    assert plain_end < 1.0 and learnt_end < 1.0  # at rest (pace 0) both settle on the goal


def test_the_start_is_identified_in_a_fixed_hold_on_a_simulated_clock_and_while_held_in_real_time():
    """Lock-step: the platform held a fixed time after the identification, whatever it took in
    wall time (the same seed gives the same figures); real time: held cycle by cycle for as
    long as the identification runs (in a process of its own: the tasks are picklable, the
    standard library's here), its error raised in the caller."""
    import functools
    import math
    import time

    from cdprctl.calibration import geometry_moves as gp

    held: list[float] = []
    ses = SimpleNamespace(run=held.append, driver=SimpleNamespace(clock=lambda: 0.0))
    assert gp.held_while(ses, lambda: np.ones(6)).tolist() == [1.0] * 6  # type: ignore[arg-type]
    assert held == [gp.HOLD_AFTER_IDENTIFYING]
    held.clear()

    def hold(duration: float) -> None:
        held.append(duration)
        time.sleep(0.01)

    ses = SimpleNamespace(run=hold, driver=SimpleNamespace(clock=time.monotonic))
    assert gp.held_while(ses, functools.partial(time.sleep, 0.3)) is None  # type: ignore[arg-type]
    assert len(held) >= 20 and set(held) == {0.05}  # held for the 0.3 s and the child's start
    with pytest.raises(ValueError, match="math domain error"):
        gp.held_while(ses, functools.partial(math.sqrt, -1.0))  # type: ignore[arg-type]


def test_the_position_held_cables_are_damped_on_their_filtered_tension_after_the_brakes_open():
    """Integral force feedback on the position-held cables: nothing while the brakes open
    (the torques are not tensions yet), then each cable 20 N above its goal paid out towards
    20 N over its stiffness (the leaky integral's rest: error / k), the force cables left to
    their own loop, the targets moved by the give over the drum ratio."""
    model = load_robot(CONFIG / "cogiro.toml")
    m = model.n_cables
    d = _Driver(m)
    ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
    assert ses.iff == pytest.approx(0.5 * model.control.force_feedback * 49.414, rel=1e-3)
    ses.force[7] = True
    ses.tension_goal[:] = 300.0
    d.states.torque[:] = ses.ratio * 320.0
    ses.states = d.states
    release = model.drives.brake_release_time
    ses.run(release - d.period)  # the brakes opening
    assert np.all(ses.give == 0.0) and np.all(ses.filtered == 300.0)
    ses.run(3.0)
    rest = 20.0 / ses.k
    assert ses.give[:7] == pytest.approx(rest[:7], rel=1e-3) and ses.give[7] == 0.0
    assert ses.targets[:7] == pytest.approx(ses.base[:7] + ses.correction[:7]
                                            - ses.give[:7] / ses.ratio[:7])  # fmt: skip


def test_a_run_ends_after_the_cycle_its_step_says_and_says_how_long_it_ran():
    model = load_robot(CONFIG / "rowc.toml")
    d = _Driver(model.n_cables)
    ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
    fractions: list[float] = []

    def each(f: float) -> bool:
        fractions.append(f)
        return len(fractions) == 3

    assert ses.run(1.0, each) == pytest.approx(3 * d.period)
    assert len(d.sent) == 3 and fractions == pytest.approx([0.004, 0.008, 0.012])
    assert ses.run(0.02) == pytest.approx(0.02) and len(d.sent) == 8


def test_a_move_that_stops_ends_there_and_counts_only_the_time_it_moved():
    """A tension beyond its stop after 40 cycles of a 10 s move: the move ends on that cycle
    (the rest of its time was holding still), the fraction done where the ramp had got."""
    from cdprctl.calibration import geometry_moves as gp
    from cdprctl.calibration.geometry_plan import GeometryOptions

    model = load_robot(CONFIG / "rowc.toml")
    m = model.n_cables
    d = _Driver(m)
    ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
    ses.states = d.states
    d.states.torque[:] = ses.ratio * 100.0  # every cable at 100 N, inside its limits
    calls = [0]

    def stops() -> bool:
        calls[0] += 1
        return calls[0] > 40

    ses.move_stops = stops  # type: ignore[method-assign]
    opt = GeometryOptions.of(model, speed=0.1)
    a, b = np.zeros(6), np.array([1.0, 0, 0, 0, 0, 0])  # 1 m: 10 s at 0.1 m/s

    def goal_of(x):
        return np.full(m, x[0]), np.full(m, 100.0)

    done, took = gp.move(ses, a, b, goal_of, opt)
    assert took == pytest.approx(41 * d.period)
    f = 40 / round(10.0 / d.period)
    assert done == pytest.approx(0.5 - 0.5 * math.cos(math.pi * f))
    assert ses.pace == 0.0
    calls[0] = -10**9  # a retreat (stop=False) runs its whole way whatever the tensions
    done, took = gp.move(ses, b, a, goal_of, opt, stop=False)
    assert (done, took) == (pytest.approx(1.0), pytest.approx(10.0))


def test_a_stopped_move_backs_off_a_tenth_of_a_metre_or_to_where_it_came_from():
    from cdprctl.calibration import geometry_moves as gp

    origin = np.zeros(6)
    far = np.array([0.6, 0.8, 0.0, 0.0, 0.0, 0.0])  # 1 m away
    assert gp.retreat_to(far, origin) == pytest.approx(far * 0.9)
    near = np.array([0.03, 0.0, 0.0, 0.0, 0.04, 0.0])  # 0.05 (m and rad) away
    assert gp.retreat_to(near, origin) == pytest.approx(origin)
    assert gp.RETREAT_DISTANCE == 0.1
