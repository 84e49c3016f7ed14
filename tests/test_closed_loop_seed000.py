"""The controller against the simulated Sensors 2019 robot (soft springs, k = 1000 N/m, 150 kg)
in lock-step: start without a jump, point-to-point motions, a 30 N lateral force. Its
suspension modes sit near 1 Hz, so config/seed000.toml runs a 0.3 Hz pose loop and gentle
motions; the springs' stretch is estimated from the feed-forward tensions (docs/control.md)."""

from __future__ import annotations

import numpy as np
import pytest
from test_closed_loop import enabled, static_deflection

from cdprctl.control.states import State
from cdprctl.rotation import log_so3
from sim_backend.faults import FaultEvent, FaultInjector


def test_start_holds_the_pose_without_a_jump(seed000):
    with enabled(seed000) as cl:
        cl.run(1.0)
        a = cl.arrays()
        assert np.abs(a["p_true"] - seed000.home.position).max() < 0.1e-3  # m
        assert np.all(a["tensions"] >= seed000.tension_min - 1e-9)


@pytest.mark.parametrize("offset", [[0.1, 0.05, 0.05], [-0.15, -0.1, 0.1]])
def test_point_to_point(seed000, offset):
    goal = seed000.home.position + np.array(offset)
    with enabled(seed000) as cl:
        # the pose's rotation vector is absolute (base frame): keep the home's 30° roll
        cl.command("move", pose=np.concatenate([goal, log_so3(seed000.home.rotation)]))
        cl.run(8.0)
        c = cl.controller
        assert c.state is State.ENABLED, c.fault_reason
        a = cl.arrays()
        assert np.linalg.norm(a["p_true"] - a["p_des"], axis=1).max() < 2e-3  # m
        assert np.linalg.norm(cl.plant.position - goal) < 1e-3  # m
        assert np.all(a["tda_ok"])
        assert np.all(a["tensions"] <= seed000.tension_max + 1e-9)


def test_lateral_force_deflects_the_springs_as_the_stiffness_predicts(seed000):
    """30 N along y, unknown to the controller: the springs stretch unseen (the encoders hold
    their pose), so the platform settles where K⁻¹ δw says (23 mm), without a fault."""
    with enabled(seed000) as cl:
        FaultInjector(
            [FaultEvent(cl.net.time, "external_wrench", value=(0.0, 30.0, 0, 0, 0, 0), ramp=1.0)]
        ).attach(cl.net)
        cl.run(12.0)
        c = cl.controller
        assert c.state is State.ENABLED, c.fault_reason
        y = cl.arrays()["p_true"][-250:, 1] - seed000.home.position[1]
        assert float(np.mean(y)) == pytest.approx(static_deflection(seed000, c.tensions), rel=0.1)


def test_switching_the_distribution_blends_instead_of_faulting(seed000):
    """set_tda barycenter → energy (minimum of energy) while holding: the new tensions take
    over in BLEND_TIME, every blend holding the wrench, so the soft cables' stretch moves
    smoothly and the pose estimate does not take it for an encoder fault (a step faulted at
    once: residual 20.5 mm > 20 mm)."""
    from cdprctl.control.distribution import Distribution
    from cdprctl.tda import TDAMethod, TDAOptions

    with enabled(seed000) as cl:
        cl.run(1.0)
        before = cl.controller.tensions.copy()
        cl.command("set_tda", tda=TDAOptions(method=TDAMethod.ENERGY, period=cl.period))
        cl.run(4.0)
        c = cl.controller
        assert c.state is State.ENABLED, c.fault_reason
        a = cl.arrays()
        steps = np.abs(np.diff(a["tensions"], axis=0)).max()
        assert steps < 1.0  # N per cycle; the switch moves some cables by 10-20 N in all
        assert np.abs(c.tensions - before).max() > 5.0  # it did switch
        assert np.abs(a["p_true"] - seed000.home.position).max() < 2e-3
        assert Distribution.BLEND_TIME == 1.0


def test_the_same_distribution_again_changes_nothing(seed000):
    from cdprctl.tda import tda_options_of

    with enabled(seed000) as cl:
        c = cl.controller
        tda = c.tda
        cl.command("set_tda", tda=tda_options_of(seed000))
        cl.run(0.1)
        assert c.tda is tda and c.distribution.old is None
        assert "unchanged" in c.events[-1][1]


def test_sotda_runs_in_the_loop_on_the_spring_robot(seed000):
    """SOTDA ν = 0.9 (stiffest along z) drives the spring robot through a move: its tensions,
    far from the barycenter's, are what the springs' stretch is estimated from, and the pose
    estimate follows (the check of the encoders against the pose once tripped at 77 mm)."""
    from cdprctl.tda import TDAMethod, TDAOptions

    goal = seed000.home.position + np.array([0.1, 0.0, 0.05])
    with enabled(seed000) as cl:
        sotda = TDAOptions(method=TDAMethod.SOTDA, nu=0.9, direction=(0.0, 0.0, 1.0),
                           period=cl.period)  # fmt: skip
        cl.command("set_tda", tda=sotda)
        cl.run(2.0)
        cl.command("move", pose=np.concatenate([goal, log_so3(seed000.home.rotation)]))
        cl.run(6.0)
        c = cl.controller
        assert c.state is State.ENABLED, c.fault_reason
        assert c.tda.options.method is TDAMethod.SOTDA and c.tda_status.name == "OK"
        a = cl.arrays()
        assert np.linalg.norm(a["p_true"] - a["p_des"], axis=1).max() < 2e-3  # m
        assert np.linalg.norm(cl.plant.position - goal) < 1e-3  # m
