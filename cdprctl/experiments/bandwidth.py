"""The closed loop's bandwidth per axis, lock-step: the reference moved by a small sinusoid
along one of the trajectory's six coordinates (x, y, z and the rotation vector from the home
orientation), the simulated platform's pose fitted by a sinusoid of the same frequency.
Gain = the platform's amplitude over the reference's (1 at low frequency; the −3 dB
bandwidth is where it falls below 1/√2), phase = its lag (rad)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.model.robot import RobotModel
from cdprctl.motion.trajectory import pose_coordinates

AXES = ("x", "y", "z", "roll", "pitch", "yaw")
#: m for x, y, z; rad for the rotation vector's components: small, the loop stays linear
AMPLITUDE = (1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-3)
SETTLE_PERIODS = 2  # of the sinusoid before the fit: the start's transient dies out
FIT_PERIODS = 4


@dataclass(frozen=True)
class Response:
    axis: int
    frequency: float  # Hz
    gain: float  # platform amplitude / reference amplitude
    phase: float  # rad, the platform's lag behind the reference (positive: behind)
    state: str  # the controller's state at the end (a fault ends the measurement)


def _fit(t: np.ndarray, y: np.ndarray, w: float) -> complex:
    """The complex amplitude of ``y`` at ``w`` rad/s (least squares with an offset)."""
    A = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    a, b, _ = np.linalg.lstsq(A, y, rcond=None)[0]
    return complex(a, b)  # y ≈ a sin + b cos = Im((a + ib) e^{iwt}) up to the offset


def response(model: RobotModel, axis: int, frequency: float) -> Response:
    """The platform's response to the reference moved by ``AMPLITUDE[axis]`` sin(2π f t)
    along ``axis``, from the robot held at home."""
    w = 2.0 * math.pi * frequency
    amp = AMPLITUDE[axis]
    with ClosedLoop(model) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(1.0, record=False)
        tr = cl.controller.trajectory
        x0 = tr.position.copy()
        t0 = cl.net.time
        times: list[float] = []
        ref: list[float] = []
        got: list[float] = []

        def drive(cl: ClosedLoop) -> None:
            # the reference of the next cycle (the trajectory holds still: it does not
            # overwrite what is set here)
            s = cl.net.time - t0
            tr.position[:] = x0
            tr.position[axis] += amp * math.sin(w * s)
            tr.velocity[:] = 0.0
            tr.velocity[axis] = amp * w * math.cos(w * s)
            tr.acceleration[:] = 0.0
            tr.acceleration[axis] = -amp * w * w * math.sin(w * s)
            times.append(s)
            ref.append(float(tr.position[axis] - x0[axis]))
            got.append(float(pose_coordinates(model, cl.plant.position, cl.plant.R)[axis]))

        periods = SETTLE_PERIODS + FIT_PERIODS
        cl.run(periods / frequency, each=drive, record=False)
        state = cl.controller.data.state
        t = np.array(times)
        keep = t >= SETTLE_PERIODS / frequency
        # both at the same instants: the lag includes the loop's period of delay
        r = _fit(t[keep], np.array(ref)[keep], w)
        y = _fit(t[keep], np.array(got)[keep] - x0[axis], w)
        gain = abs(y) / abs(r)
        phase = math.remainder(float(np.angle(r) - np.angle(y)), 2.0 * math.pi)
        ok = state in (State.ENABLED, State.MOVING)
        return Response(axis, frequency, gain if ok else math.nan, phase, state.value)


def bandwidth(responses: list[Response]) -> float:
    """Hz: where the gain first falls below 1/√2, interpolated in log frequency between the
    measured ones; ``inf`` if it never does, ``nan`` if the first one already does."""
    limit = 1.0 / math.sqrt(2.0)
    prev: Response | None = None
    for r in sorted(responses, key=lambda r: r.frequency):
        if not r.gain >= limit:  # nan (a fault) counts as fallen
            if prev is None or not math.isfinite(r.gain):
                return prev.frequency if prev is not None else math.nan
            u = (prev.gain - limit) / (prev.gain - r.gain)
            return math.exp(math.log(prev.frequency) + u * math.log(r.frequency / prev.frequency))
        prev = r
    return math.inf
