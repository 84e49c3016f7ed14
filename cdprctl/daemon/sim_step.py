"""``cdprctl run --sim``: the simulated robot in the daemon's process, on in-process buses
(``sim_backend.network.SimulatedRobot``, the recipe lock-step uses), stepped by the loop's clock
before each cycle and pushed by the demo's lateral force."""

from __future__ import annotations

import time
from typing import Any

from cdprctl.model.robot import RobotModel


class SimStepper:
    def __init__(self, model: RobotModel, as_built: RobotModel | None = None):
        """``as_built``: the robot the plant is (its geometry), the drives ``model``'s."""
        from sim_backend.network import SimulatedRobot
        from sim_backend.plant import CdprPlant

        plant = CdprPlant(as_built) if as_built is not None else None
        self.robot = SimulatedRobot(model, plant=plant)
        self.plant, self.net = self.robot.plant, self.robot.net
        self._driver: Any = None
        self._last_t: float | None = None

    def driver(self, period: float) -> Any:
        """The daemon's driver on the simulated buses: its start-up calls wait in real time
        while the simulated robot keeps time."""
        net = self.net

        def wait(dt: float) -> None:
            net.advance(dt)
            time.sleep(dt)

        self._driver = self.robot.driver(period, wait=wait)
        return self._driver

    def step(self, t: float) -> None:
        """Before the cycle at ``t`` (the loop's clock, s): the simulated robot follows the
        loop's clock, skipped periods included: the last cycle's frames handled at the time
        they were sent, then the physics up to this cycle. (Stepped after the cycle instead,
        every frame was handled a cycle's time late: after a late cycle the drives took a
        three-period target step at the last interval and faulted on their following error,
        `--sim --no-realtime` under load.) The frames were sent when the last cycle's
        computation ended (the targets are for that instant: drivers/cia402 carries them to
        it), not when it started."""
        dt = 0.0 if self._last_t is None else t - self._last_t
        sent = 0.0 if self._last_t is None else self._driver.sent_at - self._last_t
        self._last_t = t
        # all of a stall (capped at 0.05 s, the simulated robot fell behind the loop by the
        # rest of a longer one, and its drives saw the next SYNC as a target step)
        self.net.advance(min(max(dt, 0.0), self.net.MAX_CATCH_UP), sent_after=sent)

    def disturb(self, force: float) -> None:
        """A lateral force ``force`` N along y at the platform, ramped over 1 s from now."""
        from sim_backend.faults import FaultEvent

        value = (0.0, force, 0.0, 0.0, 0.0, 0.0)
        self.schedule([FaultEvent(self.net.time, "external_wrench", value=value, ramp=1.0)])

    def schedule(self, events: list) -> None:
        """``sim_backend.faults.FaultEvent``s (simulated time, s), beside those scheduled."""
        from sim_backend.faults import FaultInjector

        if self.net.faults is None:
            FaultInjector(events).attach(self.net)
        else:
            self.net.faults.events.extend(events)

    def close(self) -> None:
        self.net.close()
