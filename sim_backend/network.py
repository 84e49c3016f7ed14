"""The simulated robot behind the CAN boundary: drive emulators on python-can buses + physics.

``advance(dt)`` is one step of simulated time: frames waiting on the buses are handled at the
current time (a SYNC latches the RPDOs and samples the TPDOs), heartbeats and timeouts are
checked, then the physics integrates ``dt``. In lock-step (tests) the controller calls it after
each of its cycles; in real time (``cdprctl sim``) a loop calls it against the wall clock.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Callable
from typing import Any

import can

from cdprctl.model.robot import RobotModel
from drivers.buses import media_key, open_bus
from drivers.cia402 import protocol as p402
from sim_backend.drives.cia402 import Cia402Drive
from sim_backend.drives.load_cell import load_cell_nodes
from sim_backend.plant import CdprPlant


class SimNetwork:
    def __init__(
        self,
        model: RobotModel,
        plant: CdprPlant,
        bus_overrides: dict[str, Any] | None = None,
        start_time: float = 0.0,
        encoders: str = "absolute",
    ):
        """``encoders``: "absolute" (each counter reads the plant's motor angle, zero at the
        home pose) or "incremental" (each counter starts at zero wherever the motor stands
        and restarts at a drive reset: docs/homing.md)."""
        self.model = model
        self.plant = plant
        self.cfg = model.drives
        self.time = start_time
        # buses that an override puts on one medium share its one socket: each frame read once
        # and handled for every bus on it (with four sockets on one udp_multicast group, a
        # 1 kHz rowc decoded each frame four times, its own echoes too: the simulated robot
        # was late by 10-65 ms every second and the daemon faulted on silent drives)
        keys = [media_key(b, bus_overrides, i) for i, b in enumerate(self.cfg.buses)]
        self.buses: list[can.BusABC] = []
        for i, bus_cfg in enumerate(self.cfg.buses):
            first = keys.index(keys[i])
            self.buses.append(self.buses[first] if first < i
                              else open_bus(bus_cfg, bus_overrides, i))  # fmt: skip
        self._media = [(i, [b for b, k in enumerate(keys) if k == keys[i]])
                       for i in range(len(keys)) if keys.index(keys[i]) == i]  # fmt: skip
        # the media that send a step's frames together (drivers/pair_bus.py, udp_bus.py)
        self._stage_of = [getattr(bus, "stage", None) for bus in self.buses]
        self._batching = False
        self.protocol = self.cfg.driver
        self.nodes: list[dict[int, Any]] = []
        self.drives: list[Any] = [None] * model.n_cables
        self.rpdo_owners: list[dict[int, Any]] = []  # per bus: RPDO COB-ID → drive
        for bcfg in self.cfg.buses:
            table: dict[int, Any] = {}
            owners: dict[int, Any] = {}
            self.rpdo_owners.append(owners)
            for c, n in zip(bcfg.cables, bcfg.node_ids, strict=True):
                drive = self._drive(c, n, owners, encoders)
                table[n] = drive
                self.drives[c] = drive
            self.nodes.append(table)
        self.frames_in = 0
        self.frames_out = 0
        self.frames_refused = 0  # frames the bus would not take (its link down)
        # fault injection hooks (sim_backend.faults.FaultInjector.attach)
        self.tx_filter: Any = None  # (msg, t, bus) -> the frames really sent
        self.rx_filter: Any = None  # (msg, t) -> False: the frame is lost
        self.faults: Any = None
        self._bus_of = {c: b for b, bc in enumerate(self.cfg.buses) for c in bc.cables}
        self.load_cells = {}  # cable → its load cell's node ([[sensors.load_cells]])
        for cell, node in load_cell_nodes(model, plant):
            self.nodes[cell.bus][cell.node_id] = self.load_cells[cell.cable] = node
        # powered on: each CiA 402 drive's boot-up message (CiA 301 §7.2.8.2, INITIALISATION
        # → PRE-OPERATIONAL), heard by whoever already listens (candump, a master)
        if self.protocol != "odrive":
            for b, table in enumerate(self.nodes):
                self._send(b, [m for d in table.values() for m in d.boot_up()])

    def _drive(self, c: int, n: int, owners: dict[int, Any], encoders: str) -> Any:
        """Cable ``c``'s simulated drive, node ``n``, of the robot file's protocol (a CiA 402
        drive takes its RPDOs' COB-IDs into its bus's ``owners``)."""
        w = self.model.cables[c].winch
        if self.protocol == "odrive":
            from sim_backend.drives.odrive import ODriveAxis

            drive: Any = ODriveAxis(
                n, c, self.plant, w.torque_limit, self.cfg.comm_timeout,
                self.cfg.torque_constant,
            )  # fmt: skip
        else:
            drive = Cia402Drive(
                n, c, self.plant, self.cfg.rated_torque, w.encoder_counts_per_rev,
                w.torque_limit, self.cfg.comm_timeout, self.cfg.position_gains(w.rotor_inertia),
                owners, self.cfg.target_extrapolation,
            )  # fmt: skip
        if encoders == "incremental" and self.protocol != "odrive":
            drive.axis.incremental = True
            drive.axis.zero_counter()
        return drive

    def bus_index_of(self, cable: int) -> int:
        return self._bus_of[cable]

    def node_of(self, cable: int) -> int:
        """The node id of ``cable``'s drive (its frames' low 7 bits)."""
        return int(self.drives[cable].node_id)

    def power_cycle(self, cable: int) -> None:
        """Fault injection: the drive of ``cable`` loses power and boots (its boot-up message
        on its bus)."""
        self._send(self._bus_of[cable], self.drives[cable].power_cycle())

    def close(self) -> None:
        for m, _ in self._media:
            self.buses[m].shutdown()
        self.buses = []

    def __enter__(self) -> SimNetwork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _send(self, b: int, msgs: list[can.Message]) -> None:
        for msg in msgs:
            out = [msg] if self.tx_filter is None else self.tx_filter(msg, self.time, b)
            for m in out:
                m.timestamp = self.time
                self._put(b, m)

    def _put(self, b: int, msg: can.Message) -> None:
        stage = self._stage_of[b] if self._batching else None
        # staged (counted when flushed); a full batch flushed first
        if stage is not None and (stage(msg) or (self._flush(b) >= 0 and stage(msg))):
            return
        try:
            self.buses[b].send(msg)
        except can.CanError:  # the link down: the frame is lost, as on a real bus
            self.frames_refused += 1
            return
        self.frames_out += 1

    def process(self, first: can.Message | None = None) -> None:
        """Handle every frame waiting on every bus, at the current time (``first``: a frame
        already taken from bus 0)."""
        for b, msg in self._waiting(first):
            self._handle(b, msg)

    def _waiting(self, first: can.Message | None) -> list[tuple[int, can.Message]]:
        """Every frame waiting, as ``(bus, frame)`` for each bus on the medium it came on."""
        out: list[tuple[int, can.Message]] = []
        for m, sharing in self._media:
            bus = self.buses[m]
            while True:
                msg: can.Message | None
                if first is not None and m == 0:
                    msg, first = first, None
                else:
                    try:
                        msg = bus.recv(0)
                    except can.CanError:  # the link down: nothing to read from it now
                        msg = None
                if msg is None:
                    break
                self.frames_in += 1
                out += [(b, msg) for b in sharing]
        return out

    def _handle(self, b: int, msg: can.Message) -> None:
        if self.rx_filter is not None and not self.rx_filter(msg, self.time):
            return
        if self.protocol == "odrive":
            self._send(b, self._odrive_frame(self.nodes[b], msg, self.time))
        else:
            self._send(b, self._cia402_frame(b, msg, self.time))

    def _cia402_frame(self, b: int, msg: can.Message, t: float) -> list[can.Message]:
        if msg.is_extended_id or msg.is_remote_frame:
            return []
        table = self.nodes[b]
        arb, data = msg.arbitration_id, bytes(msg.data)
        if arb == p402.NMT and len(data) == 2:
            booted: list[can.Message] = []
            for n, d in table.items():
                if data[1] in (0, n):
                    booted += d.on_nmt(data[0])
            return booted
        if arb == p402.SYNC:
            out: list[can.Message] = []
            for d in table.values():
                out += d.on_sync(t, data)
            return out
        owner = self.rpdo_owners[b].get(arb)
        if owner is not None:  # an RPDO, to the drive whose mapping has this COB-ID
            owner.on_rpdo(data, t)
            return []
        if p402.SDO_RX < arb <= p402.SDO_RX + 127 and (arb - p402.SDO_RX) in table:
            reply = table[arb - p402.SDO_RX].on_sdo(data)
            return [reply] if reply is not None else []
        return []  # heartbeats of the controller, foreign ids: ignored, as a drive would

    def _odrive_frame(self, table: dict[int, Any], msg: can.Message, t: float) -> list[can.Message]:
        if msg.is_extended_id:
            return []
        node, cmd = msg.arbitration_id >> 5, msg.arbitration_id & 0x1F
        d = table.get(node)
        if d is None:
            return []
        return d.on_frame(cmd, bytes(msg.data), msg.is_remote_frame, t)

    def tick(self) -> None:
        for b, table in enumerate(self.nodes):
            out: list[can.Message] = []
            for d in table.values():
                out += d.tick(self.time)
            self._send(b, out)

    def _flush(self, b: int) -> int:
        """Send bus ``b``'s staged frames (one datagram on a socket pair); the number sent."""
        bus: Any = self.buses[b]
        n = bus.staged
        sent = bus.flush() if n else 0
        self.frames_out += sent
        self.frames_refused += n - sent
        return sent

    def advance_until(
        self, t_end: float, arrival: Callable[[can.Message], float], first: can.Message | None
    ) -> None:
        """(Real time: every frame this step sends goes out together at its end, on a medium
        that batches them — the daemon reads a SYNC's answers in one system call, not one per
        drive.)"""
        self._batching = True
        try:
            self._advance_until(t_end, arrival, first)
        finally:
            self._batching = False
            for m, _ in self._media:
                if self._stage_of[m] is not None:
                    self._flush(m)

    def _advance_until(
        self, t_end: float, arrival: Callable[[can.Message], float], first: can.Message | None
    ) -> None:
        """Real time: up to ``t_end`` (s), each waiting frame handled at the instant it
        arrived (``arrival(msg)``, s of simulated time, kept within [now, ``t_end``]) with
        the physics stepped up to it. A simulator woken late by a loaded machine still sees
        the SYNCs a period apart: handling a burst at its wake-up, intervals of 0 and 11 ms
        made the drives' interpolation step and fault on their following error mid-move."""
        self._faults_for(t_end - self.time)
        waiting = [(arrival(msg), b, msg) for b, msg in self._waiting(first)]
        # frames stamped after t_end came while this process was held up after reading the
        # clock: the time has passed (bunched at t_end they made SYNC intervals of 0)
        t_end = max([t_end, self.time] + [a for a, _, _ in waiting if math.isfinite(a)])
        frames = [(min(max(a, self.time), t_end), b, msg) for a, b, msg in waiting]
        frames.sort(key=lambda f: f[0])
        for t, b, msg in frames:
            if t - self.time > 0.5 * self.plant.opt.physics_dt:
                self._physics_for(t - self.time)
            self._handle(b, msg)
        self.tick()
        self._physics_for(t_end - self.time)

    def advance(
        self, dt: float, first: can.Message | None = None, sent_after: float = 0.0
    ) -> None:
        """``dt`` seconds, the frames waiting handled ``sent_after`` s into them (default at
        once; the daemon's ``--sim`` robot: when the last cycle sent them, at the end of its
        computation, not at its start)."""
        self._faults_for(dt)
        sent_after = min(max(sent_after, 0.0), dt)
        self._physics_for(sent_after)
        self.process(first)
        self.tick()
        self._physics_for(dt - sent_after)

    def _faults_for(self, dt: float) -> None:
        """The injected faults over the next ``dt`` s; delayed frames due now sent again."""
        if self.faults is not None:
            self.faults.apply(self, self.time, dt)
            for b, msg in self.faults.release(self.time):
                self._put(b, msg)  # past the filter already: not delayed or dropped again

    # s: the most of a stall of whoever steps it that the simulated robot catches up on
    # (``cdprctl sim``, ``cdprctl run --sim``); a longer one is lost time
    MAX_CATCH_UP = 0.5

    def _physics_for(self, dt: float) -> None:
        """``dt`` s of physics, the drives ticked at each instant one of them stops its
        position target within it (a step longer than their extrapolation — a stalled loop in
        lock-step, a simulator catching up — went on extrapolating to its end: the drives of
        a real robot hold)."""
        end = self.time + dt
        while (hold := self._next_hold(end)) < end:
            self._step(hold - self.time)
            self.time = hold  # exactly: the drive compares it with the same sum
            self.tick()
        self._step(end - self.time)

    def _next_hold(self, end: float) -> float:
        """s: the earliest instant before ``end`` a drive stops extrapolating, else ``end``."""
        first = end
        if self.protocol == "cia402":
            for d in self.drives:
                first = min(first, d.axis.holds_at())
        return max(first, self.time)

    def _step(self, dt: float) -> None:
        if dt > 0:
            self.plant.step(dt)
            self.time += dt


class SimulatedRobot:
    """The simulated robot on in-process buses of its own: the plant, its drives
    (``SimNetwork``) and the bus settings a driver joins them with. One recipe for lock-step
    (``LockStep``) and for the daemon's ``--sim``; ``driver`` builds the controller's side."""

    def __init__(
        self, model: RobotModel, plant: CdprPlant | None = None, encoders: str = "absolute"
    ):
        tag = uuid.uuid4().hex[:12]
        channels = [f"cdprctl-sim-{tag}-{b}" for b in range(len(model.drives.buses))]
        # a second driver (a restarted daemon) can join the same buses with these
        self.overrides: dict[str, Any] = {"interface": "inprocess", "channels": channels}
        self.model = model
        self.plant = plant or CdprPlant(model)
        self.net = SimNetwork(model, self.plant, self.overrides, encoders=encoders)

    def driver(
        self,
        period: float,
        name: str | None = None,
        clock: Callable[[], float] | None = None,
        wait: Callable[[float], None] | None = None,
    ) -> Any:
        """The robot's driver (``[drives] driver``, or ``name``) on these buses; ``clock`` and
        ``wait`` as ``drivers.create_driver`` takes them."""
        from drivers import create_driver

        kw: dict[str, Any] = {} if clock is None else {"clock": clock}
        if wait is not None:
            kw["wait"] = wait
        return create_driver(self.model, name, period=period, bus_overrides=self.overrides, **kw)


class LockStep:
    """In-process, deterministic: a driver and the simulated robot sharing a simulated clock.

    The driver's ``wait`` advances the simulation, so blocking set-up calls work unchanged;
    ``cycle(torques)`` is one control period: read, write, advance.
    """

    def __init__(
        self,
        model: RobotModel,
        period: float | None = None,
        driver: str | None = None,
        plant: CdprPlant | None = None,
        encoders: str = "absolute",
    ):
        robot = SimulatedRobot(model, plant, encoders)
        self.overrides = robot.overrides
        self.model = model
        self.period = period = period if period is not None else model.control.period
        self.plant = robot.plant
        self.net = robot.net
        self.driver = robot.driver(period, driver, clock=self.clock, wait=self.net.advance)

    def clock(self) -> float:
        return self.net.time

    def cycle(self, torques: Any) -> None:
        t = self.net.time
        self.driver.read(t)
        self.driver.write(t, torques)
        self.net.advance(self.period)

    def close(self) -> None:
        self.driver.shutdown()
        self.net.close()

    def __enter__(self) -> LockStep:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
