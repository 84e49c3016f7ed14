"""What a friction calibration measured so far (:class:`FrictionProgress`): its lines, the
torques' noise at rest, and every cycle's sample of the round trips completed, so that a
calibration stopped midway (a drive fault, a feedback timeout, a move that neared a tension
limit) keeps them (``progress.CalibrationStoppedError``, a partial session in the state directory:
``partial_session.py``) and ``--resume`` goes on from the first round trip not yet made, the
fit taking every sample (docs/friction.md). A round trip stopped midway is dropped: out and back
at one speed is what cancels the statics."""

from __future__ import annotations

import base64
import dataclasses
import time
from typing import Any

import numpy as np


@dataclasses.dataclass
class FrictionProgress:
    start: np.ndarray  # 6: m, rotation vector from home: where every line starts
    ends: list[np.ndarray]  # each line's far end (6)
    noise: np.ndarray  # N·m per winch: the torques' standard deviation at rest
    # each round trip done, its samples one a cycle: line, clock (s), motor angles (rad),
    # speeds (rad/s), torques (N·m), the cells' tensions (N, NaN: none) —
    # ``friction_procedure``'s layout; joined only once the drives are off (a copy of every
    # sample between two round trips held the drives without a SYNC for up to 130 ms)
    trips: list[np.ndarray]
    done: int = 0  # round trips completed, in the plan's order (line, speed, repeat)
    moved: float = 0.0  # s the platform moved in them
    stopped_theta: np.ndarray | None = None  # rad: the motors where a stop left them
    started: float = dataclasses.field(default_factory=time.time)  # s since the epoch
    drives_reset: str = ""  # as ``progress.Progress``'s (``check_reference``)

    @property
    def samples(self) -> int:
        return sum(len(t) for t in self.trips)

    @property
    def rows(self) -> np.ndarray:
        """Every sample kept, in order (a copy)."""
        return np.concatenate(self.trips) if self.trips else np.empty((0, 0))

    def to_data(self) -> dict[str, Any]:
        """JSON: the samples as their float64 bytes in base64 (~10⁵ rows of 34 numbers: as
        decimal text ten times the size), the rest as Python writes floats."""
        rows = np.ascontiguousarray(self.rows, dtype="<f8")
        return {"start": [float(x) for x in self.start],
                "ends": [[float(x) for x in e] for e in self.ends],
                "noise": [float(x) for x in self.noise],
                "rows_shape": list(rows.shape),
                "rows_f64": base64.b64encode(rows.tobytes()).decode("ascii"),
                "done": self.done, "moved": self.moved,
                "stopped_theta": None if self.stopped_theta is None
                else [float(x) for x in self.stopped_theta],
                "drives_reset": self.drives_reset}  # fmt: skip

    @classmethod
    def from_data(cls, data: dict[str, Any], started: float) -> FrictionProgress:
        shape = tuple(int(n) for n in data["rows_shape"])
        rows = np.frombuffer(base64.b64decode(data["rows_f64"]), dtype="<f8").reshape(shape)
        stopped = data.get("stopped_theta")
        return cls(start=np.array(data["start"], float),
                   ends=[np.array(e, float) for e in data["ends"]],
                   noise=np.array(data["noise"], float), trips=[rows.astype(float)],
                   done=int(data["done"]), moved=float(data["moved"]),
                   stopped_theta=None if stopped is None else np.array(stopped, float),
                   started=started,
                   drives_reset=str(data.get("drives_reset", "")))  # fmt: skip
