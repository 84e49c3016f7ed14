"""Fault injection for the reliability tests: scheduled or random (seeded) events.

Kinds (``FaultEvent.kind``) and their ``value``:

* ``frame_loss`` — probability (0-1) that a frame is lost, both directions;
* ``frame_delay`` — extra latency (s) of the drives' frames (with ``cable``: of that drive's
  alone, as when one drive's answers to a SYNC arrive after the next SYNC on a busy bus);
* ``frame_corruption`` — probability that a drive frame arrives with a wrong length or byte;
* ``drive_fault`` — the drive of ``cable`` faults with error ``value`` (CiA 402 EMCY code, or
  ODrive error bits);
* ``silent_drive`` — the drive of ``cable`` stops talking (no TPDO, no heartbeat);
* ``encoder_jump`` — the encoder of ``cable`` jumps by ``value`` rad;
* ``cable_snap`` — ``cable`` breaks;
* ``winch_slip`` — ``cable`` slips on its drum at ``value`` m/s (unseen by the encoder);
* ``estop`` — the safety chain opens at every drive's STO input (an e-stop; ``value``: the
  error code the drives report, 0 for the simulated drives' own, ``EMCY_STO``), closed again
  when the event ends (CiA 402 drives; the drives keep their error until a fault reset);
* ``load_cell_dead`` — the load cell of ``cable`` stops sending (``[[sensors.load_cells]]``);
* ``load_cell_drift`` — the load cell of ``cable`` drifts at ``value`` N/s (its offset kept
  when the event ends, as a drifted cell's is);
* ``load_cell_offset`` — the load cell of ``cable`` reads ``value`` N more (a knock, a loose
  connector), taken off again when the event ends;
* ``external_wrench`` — ``value`` = (fx, fy, fz, mx, my, mz) N, N·m at P, base frame,
  ramped over ``ramp`` s (0: a step) from the wrench acting when the event starts: an event
  of zeros with a ramp takes a force off as gradually as one put it on.

Each event starts at ``time`` (s, simulated) and lasts ``duration`` (s; inf: for good).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Any

import can

from drivers.cia402.protocol import EMCY_STO

KINDS = (
    "frame_loss",
    "frame_delay",
    "frame_corruption",
    "drive_fault",
    "silent_drive",
    "encoder_jump",
    "cable_snap",
    "winch_slip",
    "external_wrench",
    "estop",
    "load_cell_dead",
    "load_cell_drift",
    "load_cell_offset",
)


@dataclass
class FaultEvent:
    time: float
    kind: str
    cable: int | None = None
    value: Any = 0.0
    duration: float = math.inf
    ramp: float = 0.0
    started: bool = field(default=False, compare=False)
    ended: bool = field(default=False, compare=False)
    # external_wrench: the wrench acting when it started, where its ramp starts from
    wrench_before: tuple[float, ...] = field(default=(0.0,) * 6, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"fault kind {self.kind!r}: one of {', '.join(KINDS)}")


def _cia402_node(arbitration_id: int) -> int:
    return arbitration_id & 0x7F  # CiA 301: function code << 7 | node id


def _odrive_node(arbitration_id: int) -> int:
    return arbitration_id >> 5  # CAN Simple: node id << 5 | command


class FaultInjector:
    """Applies :class:`FaultEvent` s to a :class:`~sim_backend.network.SimNetwork`."""

    def __init__(self, events: list[FaultEvent] | None = None, seed: int = 0):
        self.events = sorted(events or [], key=lambda e: e.time)
        self.rng = random.Random(seed)
        self.loss = 0.0
        self.delay = 0.0
        self.delay_node: int | None = None  # the one node whose frames are delayed (None: all)
        self._node_of_frame = _cia402_node
        self.corruption = 0.0
        self._delayed: list[tuple[float, int, can.Message]] = []  # (due, bus, frame)
        self.counts: dict[str, int] = {"lost": 0, "delayed": 0, "corrupted": 0}

    @classmethod
    def random_faults(
        cls,
        duration: float,
        n_cables: int,
        rate: float,
        seed: int,
        kinds: tuple[str, ...] = ("frame_loss", "encoder_jump", "drive_fault", "external_wrench"),
    ) -> FaultInjector:
        """``rate`` events per second on average, drawn with ``seed``."""
        rng = random.Random(seed)
        events: list[FaultEvent] = []
        t = rng.expovariate(rate)
        while t < duration:
            kind = rng.choice(kinds)
            cable = rng.randrange(n_cables)
            value: Any = {
                "frame_loss": rng.uniform(0.01, 0.2),
                "encoder_jump": rng.uniform(-0.5, 0.5),
                "drive_fault": 0x2310,
                "external_wrench": (*tuple(rng.uniform(-20, 20) for _ in range(3)), 0, 0, 0),
            }.get(kind, 0.0)
            events.append(FaultEvent(t, kind, cable, value, duration=rng.uniform(0.05, 0.5)))
            t += rng.expovariate(rate)
        return cls(events, seed)

    def attach(self, net: Any) -> None:
        net.tx_filter = self.tx_filter
        net.rx_filter = self.rx_filter
        net.faults = self

    # -- frames ---------------------------------------------------------------------------------
    def rx_filter(self, msg: can.Message, t: float) -> bool:
        """False: the controller's frame is lost before reaching the drives."""
        if self.loss and self.rng.random() < self.loss:
            self.counts["lost"] += 1
            return False
        return True

    def tx_filter(self, msg: can.Message, t: float, bus: int = 0) -> list[can.Message]:
        """The frames really sent for ``msg`` a drive sends on ``bus`` at ``t``: none (lost or
        delayed: ``release`` gives it back on its bus later), it, or a corrupted copy."""
        if self.loss and self.rng.random() < self.loss:
            self.counts["lost"] += 1
            return []
        if self.corruption and self.rng.random() < self.corruption:
            self.counts["corrupted"] += 1
            data = bytearray(msg.data)
            if data and self.rng.random() < 0.5:
                data[self.rng.randrange(len(data))] ^= 1 << self.rng.randrange(8)
            else:
                data = data[:-1]
            msg = can.Message(
                arbitration_id=msg.arbitration_id,
                data=bytes(data),
                is_extended_id=msg.is_extended_id,
            )
        node = self.delay_node
        if self.delay > 0 and (node is None or self._node_of_frame(msg.arbitration_id) == node):
            self.counts["delayed"] += 1
            self._delayed.append((t + self.delay, bus, msg))
            return []
        return [msg]

    def release(self, t: float) -> list[tuple[int, can.Message]]:
        """Delayed frames whose time has come, each with the bus it was sent on."""
        due = [(b, m) for when, b, m in self._delayed if when <= t]
        self._delayed = [d for d in self._delayed if d[0] > t]
        return due

    # -- events ---------------------------------------------------------------------------------
    def apply(self, net: Any, t: float, dt: float) -> None:
        plant = net.plant
        for ev in self.events:
            if ev.ended or t < ev.time:
                continue
            active = t < ev.time + ev.duration
            if not ev.started:
                ev.started = True
                self._start(net, ev)
            if not active:
                ev.ended = True
                self._end(net, ev)
                continue
            if ev.kind == "winch_slip":
                plant.drum_slip[ev.cable] += float(ev.value) * dt
            elif ev.kind == "external_wrench":
                s = 1.0 if ev.ramp <= 0 else min(1.0, (t - ev.time) / ev.ramp)
                w = [a + s * (x - a) for a, x in zip(ev.wrench_before, ev.value, strict=True)]
                plant.ext_force[:] = w[:3]
                plant.ext_moment[:] = w[3:]

    def _start(self, net: Any, ev: FaultEvent) -> None:
        c = ev.cable
        if ev.kind == "external_wrench":
            p = net.plant
            ev.wrench_before = (*p.ext_force.tolist(), *p.ext_moment.tolist())
        if ev.kind == "frame_loss":
            self.loss = float(ev.value)
        elif ev.kind == "frame_delay":
            self.delay = float(ev.value)
            self.delay_node = None if c is None else net.node_of(c)
            self._node_of_frame = _odrive_node if net.protocol == "odrive" else _cia402_node
        elif ev.kind == "frame_corruption":
            self.corruption = float(ev.value)
        elif ev.kind == "drive_fault":
            b = net.bus_index_of(c)
            net._send(b, [net.drives[c].inject_fault(int(ev.value))])
        elif ev.kind == "silent_drive":
            net.drives[c].silent = True
        elif ev.kind == "encoder_jump":
            d = net.drives[c]
            if hasattr(d, "axis"):  # CiA 402: counts
                d.axis.jump_encoder(round(float(ev.value) * d.axis.cpr / (2 * math.pi)))
            else:  # ODrive: rad
                d.encoder_offset += float(ev.value)
        elif ev.kind == "cable_snap":
            net.plant.cable_cut[c] = True
        elif ev.kind.startswith("load_cell_"):
            self._load_cell(net.load_cells[c], ev.kind, float(ev.value), 1.0)
        elif ev.kind == "estop":
            for i, d in enumerate(net.drives):
                if d is not None:
                    frames = d.open_sto(int(ev.value) or EMCY_STO, net.time)
                    net._send(net.bus_index_of(i), frames)

    @staticmethod
    def _load_cell(cell: Any, kind: str, value: float, sign: float) -> None:
        """A load cell's fault begins (``sign`` 1) or ends (-1)."""
        if kind == "load_cell_dead":
            cell.silent = sign > 0
        elif kind == "load_cell_drift":
            cell.drift_rate += sign * value
        else:
            cell.offset += sign * value

    def _end(self, net: Any, ev: FaultEvent) -> None:
        c = ev.cable
        if ev.kind == "frame_loss":
            self.loss = 0.0
        elif ev.kind == "frame_delay":
            self.delay = 0.0
        elif ev.kind == "frame_corruption":
            self.corruption = 0.0
        elif ev.kind == "silent_drive":
            net.drives[c].silent = False
        elif ev.kind.startswith("load_cell_"):
            self._load_cell(net.load_cells[c], ev.kind, float(ev.value), -1.0)
        elif ev.kind == "estop":
            for d in net.drives:
                if d is not None:
                    d.close_sto()
        elif ev.kind == "external_wrench":
            net.plant.ext_force[:] = 0.0
            net.plant.ext_moment[:] = 0.0
