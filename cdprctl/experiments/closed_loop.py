"""The controller against the simulated robot in lock-step: deterministic closed-loop runs."""

from __future__ import annotations

from typing import Any

import numpy as np

from cdprctl.control.command_types import command
from cdprctl.control.lifecycle.manager import ControllerManager
from cdprctl.model.robot import RobotModel
from sim_backend.network import LockStep


class ClosedLoop:
    """``ControllerManager`` + ``LockStep``: ``run(seconds)`` alternates one control cycle
    and one period of simulation; ``log`` keeps per-cycle arrays for the figures."""

    def __init__(self, model: RobotModel, tda: Any = None, driver: str | None = None):
        self.model = model
        self.period = model.control.period
        self.rig = LockStep(model, period=self.period, driver=driver)
        self.plant = self.rig.plant
        self.net = self.rig.net
        self.manager = ControllerManager(model, self.rig.driver, tda)
        self.controller = self.manager.controller
        self.log: dict[str, list[Any]] = {
            k: []
            for k in ("t", "state", "p_true", "p_est", "p_des", "tensions", "torques", "tda_ok")
        }

    def startup(self) -> None:
        self.manager.startup()

    def command(self, kind: str, **kw: Any) -> None:
        self.controller.submit(command(kind, **kw))

    def run(self, seconds: float, until: Any = None, each: Any = None, record: bool = True) -> None:
        """``seconds`` of control cycles and simulation; after each cycle ``each(self)`` (a
        per-cycle check), then ``until(self)`` ends the run early when true; ``record=False``
        keeps nothing in ``log``."""
        d, step = self.controller.data, self.manager.step
        for _ in range(round(seconds / self.period)):
            t = self.net.time
            step(t)
            self.net.advance(self.period)
            if record:
                lg = self.log
                lg["t"].append(t)
                lg["state"].append(d.state.value)
                lg["p_true"].append(self.plant.position.copy())
                lg["p_est"].append(d.position.copy())
                lg["p_des"].append(d.reference[:3].copy())
                lg["tensions"].append(d.tensions.copy())
                lg["torques"].append(d.torques.copy())
                lg["tda_ok"].append(d.tda_status.name == "OK")
            if each is not None:
                each(self)
            if until is not None and until(self):
                break

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.array(v) for k, v in self.log.items()}

    def close(self) -> None:
        self.rig.close()

    def __enter__(self) -> ClosedLoop:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def ramped_force(t0: float, force: float, axis: int = 1, seconds: float = 1.0) -> Any:
    """A ``run(..., each=)`` callback: ``force`` N along base ``axis`` on the simulated
    platform, ramped in over ``seconds`` from ``t0`` (s of simulated time) — the demo's jet."""

    def push(cl: ClosedLoop) -> None:
        cl.plant.ext_force[axis] = force * min(1.0, (cl.net.time - t0) / seconds)

    return push
