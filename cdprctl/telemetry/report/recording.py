"""A run recorded by ``cdprctl record`` read back for ``cdprctl report``: DIR/state.csv (one
row per state payload), DIR/timing.csv, DIR/events.csv (time, kind, text) and DIR/meta.json
(the robot's status). Times are the robot PC's monotonic clock in the files; here they are
seconds from the first recorded state, so every figure shares one time axis."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.control.states import State

#: the states in which the drives are on and the controller follows its reference (the
#: supervisor watches the tracking error in them): elsewhere the reference is stale — the
#: drives off, brakes closed, or still enabling — and "estimate − reference" is no error
TRACKING_STATES = frozenset(
    s.value for s in (State.ENABLED, State.MOVING, State.DISABLING, State.STOPPING)
)


@dataclass(frozen=True)
class Event:
    """One row of events.csv: ``time`` s from the first recorded state, ``kind`` as the
    daemon sent it (event, fault, reject, drives), ``text`` its words."""

    time: float
    kind: str
    text: str


@dataclass
class Recording:
    """``head`` and ``rows``: state.csv as read; ``t`` (s): each row's time from the first
    row's; ``t0`` (s): that first time on the robot's clock; ``meta``: meta.json's
    ``config`` ({} without it)."""

    run: Path
    head: list[str]
    rows: list[list[str]]
    t: np.ndarray
    t0: float
    meta: dict[str, Any] = field(default_factory=dict)

    def column(self, name: str) -> np.ndarray:
        """The named column as floats (empty and None cells: NaN)."""
        return column(self.head, self.rows, name)

    def has(self, name: str) -> bool:
        return name in self.head

    @property
    def states(self) -> list[str]:
        i = self.head.index("state")
        return [r[i] for r in self.rows]

    @property
    def cables(self) -> list[str]:
        return [h[2:] for h in self.head if h.startswith("t_")]

    @property
    def grippers(self) -> list[str]:
        return [h[len("grip_travel_") :] for h in self.head if h.startswith("grip_travel_")]

    def tracking(self) -> np.ndarray:
        """True on the rows whose state follows a reference (TRACKING_STATES)."""
        return np.array([s in TRACKING_STATES for s in self.states], dtype=bool)

    def position_error_mm(self) -> np.ndarray:
        """|estimate − reference| of the position (mm, base frame) on each row; NaN where the
        robot is not tracking (the drives off: the reference is stale there)."""
        err = np.sqrt(sum(self.column(f"err_{a}") ** 2 for a in "xyz")) * 1e3
        return np.where(self.tracking(), err, np.nan)

    def positions(self) -> np.ndarray:
        """(n, 3) the estimated position of each row (m, base frame)."""
        return np.column_stack([self.column(a) for a in "xyz"])

    @cached_property
    def events(self) -> list[Event]:
        """events.csv's rows within the recorded span of states (one sent before it — the
        drives' identities at start-up, a state change the recorder caught late — belongs to
        no instant on the time axis), in time order; [] without the file."""
        path = self.run / "events.csv"
        if not path.is_file():
            return []
        head, rows = read_csv(path)
        if not rows or head[:3] != ["time", "kind", "text"]:
            return []
        end = float(self.t[-1])
        out = []
        for r in rows:
            try:
                at = float(r[0]) - self.t0
            except ValueError:
                continue
            if 0.0 <= at <= end:
                out.append(Event(at, r[1], r[2] if len(r) > 2 else ""))
        return sorted(out, key=lambda e: e.time)


def read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return (rows[0], rows[1:]) if rows else ([], [])


def column(head: list[str], rows: list[list[str]], name: str) -> np.ndarray:
    i = head.index(name)
    return np.array([float(r[i]) if r[i] not in ("", "None") else np.nan for r in rows])


def load_recording(run: Path) -> Recording | str:
    """The recording in ``run``, or why there is none to draw (a sentence for the user)."""
    if not (run / "state.csv").is_file():
        return f"{run}/state.csv is missing (record a run first)"
    head, rows = read_csv(run / "state.csv")
    if not rows or "time" not in head or "state" not in head:
        return f"{run}/state.csv has no rows"
    meta: dict[str, Any] = {}
    if (run / "meta.json").is_file():
        try:
            meta = json.loads((run / "meta.json").read_text()).get("config", {}) or {}
        except (ValueError, AttributeError):
            return f"{run}/meta.json is not the robot's status as `cdprctl record` writes it"
    t = column(head, rows, "time")
    return Recording(run, head, rows, t - t[0], float(t[0]), meta)


def farthest_pair(points: np.ndarray) -> tuple[int, int]:
    """The indices (i < j) of the two rows of ``points`` (n, 3) farthest apart (Euclidean;
    rows with a NaN are never chosen; of equal rows the first; on a tie between pairs, one of
    them); (0, 0) with fewer than two finite rows. Exact: equal rows are merged, a lower
    bound from a double sweep keeps only the rows that could end a longer pair, and those
    are compared pair by pair in blocks."""
    p = np.asarray(points, dtype=float)
    finite = np.flatnonzero(np.all(np.isfinite(p), axis=1))
    if len(finite) < 2:
        return (0, 0)
    uniq, first = np.unique(p[finite], axis=0, return_index=True)
    index = finite[first]  # each distinct position's first row
    # a pair at least this long exists (farthest from a point, then from that one) ...
    a = int(np.argmax(np.linalg.norm(uniq - uniq[0], axis=1)))
    best = float(np.max(np.linalg.norm(uniq - uniq[a], axis=1)))
    # ... and a pair's ends each lie at least `best - R` from the centre c, R the largest
    c = 0.5 * (uniq.min(axis=0) + uniq.max(axis=0))
    r = np.linalg.norm(uniq - c, axis=1)
    keep = np.flatnonzero(r >= best - float(r.max()) - 1e-12)
    q = uniq[keep]
    found, pair = -1.0, (0, 0)
    for s in range(0, len(q), 512):
        d = np.linalg.norm(q[s : s + 512, None, :] - q[None, :, :], axis=2)
        k = np.unravel_index(int(np.argmax(d)), d.shape)
        if d[k] > found:
            found = float(d[k])
            pair = (int(index[keep[s + k[0]]]), int(index[keep[k[1]]]))
    i, j = sorted(pair)
    return (i, j)
