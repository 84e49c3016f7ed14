"""What a calibration measured so far (:class:`Progress`): the samples at rest, in order, and
where the plan had the platform, so that a calibration stopped midway (a drive fault, a
feedback timeout) keeps them (:class:`CalibrationStoppedError`, a partial session in the state
directory: ``cdprctl/calibration/partial_session.py``) and ``--resume`` goes on from the first pose
not yet sampled, the identification taking every sample (docs/homing.md)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.calibration.friction_progress import FrictionProgress
from cdprctl.calibration.session import CalibrationFailedError


@dataclasses.dataclass
class Progress:
    theta: list[np.ndarray] = dataclasses.field(default_factory=list)  # rad per cable
    tension: list[np.ndarray] = dataclasses.field(default_factory=list)  # N per cable
    guess: list[np.ndarray] = dataclasses.field(default_factory=list)  # the pose planned (6)
    # geometry: how many of the samples are the start's (``self``'s pattern); None: under way
    near: int | None = None
    start_targets: np.ndarray | None = None  # rad: the motors at the start (moves come back)
    here: np.ndarray | None = None  # geometry: where the plan has the platform now (6)
    moved: float = 0.0  # s the platform moved
    stopped_theta: np.ndarray | None = None  # rad: the motors where a stop left them
    started: float = dataclasses.field(default_factory=time.time)  # s since the epoch
    # why a resume was refused for the drives' reset: kept in the file, as the refused
    # resume's set-up wrote the drives' settings again and a later one could not see it
    drives_reset: str = ""

    @property
    def samples(self) -> int:
        return len(self.theta)

    def add(self, theta: np.ndarray, tension: np.ndarray, guess: np.ndarray) -> None:
        self.theta.append(np.array(theta, float))
        self.tension.append(np.array(tension, float))
        self.guess.append(np.array(guess, float))

    def arrays(self, upto: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(theta, tension, guess) of the first ``upto`` samples (all: None), K × m, m, 6."""
        n = self.samples if upto is None else upto
        return (np.array(self.theta[:n]), np.array(self.tension[:n]),
                np.array(self.guess[:n]))  # fmt: skip

    def to_data(self) -> dict[str, Any]:
        """JSON: every float as Python writes it (read back to the same bits)."""

        def rows(a: list[np.ndarray]) -> list[list[float]]:
            return [[float(x) for x in r] for r in a]

        def vec(a: np.ndarray | None) -> list[float] | None:
            return None if a is None else [float(x) for x in a]

        return {"theta": rows(self.theta), "tension": rows(self.tension),
                "guess": rows(self.guess), "near": self.near,
                "start_targets": vec(self.start_targets), "here": vec(self.here),
                "moved": self.moved, "stopped_theta": vec(self.stopped_theta),
                "drives_reset": self.drives_reset}  # fmt: skip

    @classmethod
    def from_data(cls, data: dict[str, Any], started: float) -> Progress:
        def vec(a: Any) -> np.ndarray | None:
            return None if a is None else np.array(a, float)

        p = cls(near=data.get("near"), start_targets=vec(data.get("start_targets")),
                here=vec(data.get("here")), moved=float(data.get("moved", 0.0)),
                stopped_theta=vec(data.get("stopped_theta")), started=started,
                drives_reset=str(data.get("drives_reset", "")))  # fmt: skip
        for th, t, g in zip(data["theta"], data["tension"], data["guess"], strict=True):
            p.add(np.array(th), np.array(t), np.array(g))
        return p


class CalibrationStoppedError(CalibrationFailedError):
    """A calibration stopped midway (drives disabled, brakes on): the message the fault's,
    ``progress`` what it measured (a geometric or self calibration's, a friction
    calibration's; None: nothing yet), ``at`` where it stopped (words), ``cause`` what points
    at the machine's load ("" when nothing does: ``partial_session.timing_cause``)."""

    def __init__(self, message: str, progress: Any, at: str, cause: str):
        super().__init__(message)
        self.progress, self.at, self.cause = progress, at, cause


def stopped(exc: Exception, progress: Progress | FrictionProgress | None, ses: Any,
            at: str) -> CalibrationStoppedError:  # fmt: skip
    """``exc`` (a :class:`CalibrationFailedError` or a driver's error) as a stop that keeps
    ``progress`` (None: nothing measured yet); ``ses`` the session (its missed periods, its
    driver's error)."""
    from cdprctl.calibration.partial_session import timing_cause

    cause = timing_cause(ses.driver.error, ses.missed_periods, ses.cycles)
    if progress is not None:
        progress.stopped_theta = np.array(ses.states.position, float)
    return CalibrationStoppedError(str(exc), progress, at, cause)


# m of cable: how far a motor may read from where a stop left it. The platform does not stand
# still at a stop: a faulted drive lets its cable go until its brake closes while the others
# still hold (rowc, lock-step, a drive fault mid-move: 11.9 mm); an incremental encoder reset
# since reads the whole way from where it was set up. Beyond, resuming is refused
MOVED_SINCE_STOP = 0.05


def check_reference(model: Any, driver: Any, progress: Progress | FrictionProgress,
                    identities: list[Any], path: Any, log: Any = None,
                    who: str = "") -> str:  # fmt: skip
    """"" when the drives, configured, read on the encoder reference ``progress``'s samples
    (a calibration's or a friction calibration's) were taken on (``path``: its file), else
    why not, in one line; with ``log``, a fault the drives still latch from the stop reset
    first (said by ``who``: ``partial_session.clear_latched_fault``). Why not: a drive exchanged
    (0x1018), reset since the stop (``reset_since_setup``: an incremental counter restarted),
    or a motor reading more than ``MOVED_SINCE_STOP`` of cable from where the stop left it."""
    from cdprctl.calibration.partial_session import (
        PartialSessionError,
        check_identities,
        clear_latched_fault,
        keep_in_data,
    )

    if log is not None:
        clear_latched_fault(driver, log, who)
    names = [c.name for c in model.cables]
    fix = "start over without --resume"
    if progress.drives_reset:
        return (f"the drives of cables {progress.drives_reset} were reset (power-up or NMT "
                f"reset) since {path} was measured, as an earlier --resume found (its set-up "
                f"wrote their settings again: the reset no longer shows): {fix}")  # fmt: skip
    try:
        check_identities(identities, list(getattr(driver, "identities", [])), names, path)
    except PartialSessionError as exc:
        return str(exc)
    reset = driver.reset_since_setup
    if model.drives.encoders != "absolute" and reset is not None and any(reset):
        which = ", ".join(names[i] for i, r in enumerate(reset) if r)
        progress.drives_reset = which
        if path is not None and Path(path).is_file():
            keep_in_data(Path(path), "drives_reset", which)
        return (f"the drives of cables {which} were reset (power-up or NMT reset) since {path} "
                "was measured: their incremental encoders lost the zero its samples were "
                f"taken on: {fix}")  # fmt: skip
    if progress.stopped_theta is None:
        return ""
    ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
    now = driver.read(driver.clock()).position
    off = np.abs(now - progress.stopped_theta) * ratio
    i = int(np.argmax(off))
    if off[i] > MOVED_SINCE_STOP:
        return (f"the encoder of cable {names[i]} reads {off[i] * 1e3:.1f} mm of cable from "
                f"where the stop left it (at most {MOVED_SINCE_STOP * 1e3:g} mm): its drive "
                f"was reset or the platform moved since {path} was measured: {fix}")  # fmt: skip
    return ""
