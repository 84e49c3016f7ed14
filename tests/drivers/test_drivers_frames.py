"""Frame-level tests of each protocol on python-can's ``virtual`` bus, against a scripted peer
that records what the driver sends and answers from a table, in simulated time."""

from __future__ import annotations

import contextlib
import itertools
import math
import struct
import uuid

import can
import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode

from cdprctl.robot_file import load_robot
from drivers import (
    DriveFaultError,
    DriverTimeoutError,
    DriveState,
    Lifecycle,
    create_driver,
)
from drivers.cia402 import protocol as p
from drivers.odrive import protocol as po


class ScriptedPeer:
    """Answers on a virtual bus; ``answer(msg, t)`` returns frames to send back."""

    def __init__(self, channel: str, answer):
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.answer = answer
        self.rx: list[tuple[float, int, bytes]] = []
        self.messages: list[can.Message] = []  # the same frames whole (their flags)
        self.t = 0.0

    def wait(self, dt: float) -> None:  # the driver's wait hook: time passes, the peer works
        self.pump()
        self.t += dt

    def pump(self) -> None:
        while True:
            msg = self.bus.recv(0)
            if msg is None:
                break
            self.rx.append((self.t, msg.arbitration_id, bytes(msg.data)))
            self.messages.append(msg)
            for out in self.answer(msg, self.t) or []:
                self.bus.send(out)

    def sent(self, arb: int) -> list[bytes]:
        return [d for _, a, d in self.rx if a == arb]


def frame(arb: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=arb, data=data, is_extended_id=False)


class Cia402Script:
    """A table-driven CiA 402 peer: SDO answers from a table of objects (cdprctl's torque-mode
    PDO mapping, rated torque 5 N·m, modes 8 and 10; no identity object: aborted), statusword
    per controlword, heartbeats."""

    def __init__(self, nodes, cpr=65536, rated_mnm=5000):
        self.state = {n: p.PowerState.SWITCH_ON_DISABLED for n in nodes}
        self.position = {n: 0 for n in nodes}
        self.torque = {n: 0 for n in nodes}
        self.silent: set[int] = set()
        self.drop_tpdo: set[int] = set()
        self.emcy: dict[int, int] = {}
        self.statusword: dict[int, int] = {}  # node → a statusword sent instead of its state's
        self.objects = {n: self._table(n, rated_mnm) for n in nodes}

    @staticmethod
    def _table(n: int, rated_mnm: int) -> dict[tuple[int, int], int]:
        table = {(p.OD_RATED_TORQUE, 0): rated_mnm, (p.OD_SUPPORTED_DRIVE_MODES, 0): 0x280,
                 (p.OD_MODES_OF_OPERATION, 0): 0, (p.OD_ABORT_CONNECTION, 0): 1,
                 (p.OD_MAX_TORQUE, 0): 1000, (p.OD_SYNC_COUNTER_OVERFLOW, 0): 0,
                 (p.OD_FOLLOWING_ERROR_WINDOW, 0): 1000,
                 (p.OD_FOLLOWING_ERROR_TIMEOUT, 0): 10}  # fmt: skip
        for comm, mapping, cob, entries in (
            (p.RPDO1_COMM, p.RPDO1_MAP, p.RPDO1 + n, p.RPDO1_MAPPING[p.MODE_CST]),
            (p.TPDO1_COMM, p.TPDO1_MAP, p.TPDO1 + n, p.TPDO1_MAPPING),
        ):
            table[(comm, 1)], table[(comm, 2)] = cob, 1
            table[(mapping, 0)] = len(entries)
            for k, e in enumerate(entries, 1):
                table[(mapping, k)] = e
        return table

    def __call__(self, msg, t):
        arb, data = msg.arbitration_id, bytes(msg.data)
        out = []
        if p.SDO_RX < arb <= p.SDO_RX + 127:
            n = arb - p.SDO_RX
            cmd, index, sub, raw = p.SDO_STRUCT.unpack(data)
            objects = self.objects[n]
            key = (p.OD_MODES_OF_OPERATION, 0) if index == p.OD_MODES_DISPLAY else (index, sub)
            if cmd & 0xE0 == 0x20:
                size = 4 - ((cmd >> 2) & 0x3) if cmd & 0x1 else 4
                objects[(index, sub)] = int.from_bytes(raw[:size], "little")
                out.append(frame(p.SDO_TX + n, p.SDO_STRUCT.pack(0x60, index, sub, b"\0" * 4)))
            elif key in objects:
                value = objects[key].to_bytes(4, "little")
                out.append(frame(p.SDO_TX + n, p.SDO_STRUCT.pack(0x43, index, sub, value)))
            else:  # no such object
                code = (0x06020000).to_bytes(4, "little")
                out.append(frame(p.SDO_TX + n, p.SDO_STRUCT.pack(0x80, index, sub, code)))
        elif p.RPDO1 < arb <= p.RPDO1 + 127:
            n = arb - p.RPDO1
            cw, tq = p.RPDO1_STRUCT.unpack(data)
            self.torque[n] = tq
            nxt = p.TRANSITIONS.get((self.state[n], p.command_of(cw)))
            if nxt:
                self.state[n] = nxt[0]
        elif arb == p.SYNC:
            for n, st in self.state.items():
                if n in self.silent or n in self.drop_tpdo:
                    continue
                sw = self.statusword.get(n, p.STATUSWORD_OF[st])
                out.append(
                    frame(p.TPDO1 + n, p.TPDO1_STRUCT.pack(sw, self.torque[n], self.position[n]))
                )
                out.append(frame(p.HEARTBEAT + n, bytes([p.HB_OPERATIONAL])))
            for n, code in list(self.emcy.items()):
                out.append(frame(p.EMCY + n, p.EMCY_STRUCT.pack(code, 1, b"\0" * 5)))
                self.state[n] = p.PowerState.FAULT
                del self.emcy[n]
        return out


@pytest.fixture
def seed():
    return in_torque_mode(load_robot(CONFIG / "seed000.toml"))


def make(model, script, name="cia402"):
    channel = f"frames-{uuid.uuid4()}"
    peer = ScriptedPeer(channel, script)
    drv = create_driver(
        model,
        name,
        period=0.002,
        clock=lambda: peer.t,
        wait=peer.wait,
        bus_overrides={"interface": "virtual", "channel": channel},
    )
    return drv, peer


@contextlib.contextmanager
def configured(model):
    """(driver, peer, script): eight scripted CiA 402 nodes (1-8) and the driver on their bus,
    configured; the driver shut down at the end."""
    script = Cia402Script(range(1, 9))
    drv, peer = make(model, script)
    with drv:
        drv.configure()
        yield drv, peer, script


def test_cia402_configure_frames(seed):
    with configured(seed) as (drv, peer, _):
        assert drv.lifecycle is Lifecycle.INACTIVE
        # PRE-OPERATIONAL, set-up by SDO, then NMT start (all nodes)
        assert peer.sent(p.NMT)[:2] == [bytes([0x80, 0x00]), bytes([0x01, 0x00])]
        last_sdo = max(t for t, a, _ in peer.rx if a == p.SDO_RX + 8)
        assert min(t for t, a, d in peer.rx if a == p.NMT and d[0] == 0x01) >= last_sdo
        sdo = peer.sent(p.SDO_RX + 1)
        reads = [(d[2] << 8 | d[1], d[3]) for d in sdo if d[0] == 0x40]
        # capabilities first: identity, device type, modes, rated torque, the optional
        # objects; then the heartbeat time before anything is written (a reset drive has its
        # default: docs/homing.md)
        assert reads[:13] == [(0x1018, 1), (0x1018, 2), (0x1018, 3), (0x1018, 4), (0x1000, 0),
                              (0x6502, 0), (0x6076, 0), (0x6007, 0), (0x6072, 0), (0x1019, 0),
                              (0x6065, 0), (0x6066, 0), (0x1017, 0)]  # fmt: skip
        assert (0x1600, 0) in reads and (0x1A00, 0) in reads
        writes = [d for d in sdo if d[0] & 0xE0 == 0x20]
        assert writes[0] == bytes([0x2F, 0x60, 0x60, 0x00, 0x0A, 0, 0, 0])  # 0x6060 := 10 (CST)
        assert writes[1] == bytes([0x2B, 0x17, 0x10, 0x00, 0x64, 0x00, 0, 0])  # 0x1017 := 100 ms
        assert writes[2] == bytes([0x2B, 0x07, 0x60, 0x00, 0x03, 0x00, 0, 0])  # 0x6007 := 3
        assert writes[3][:4] == bytes([0x2B, 0x72, 0x60, 0x00])  # 0x6072: the torque limit
        assert writes[4] == bytes([0x2F, 0x19, 0x10, 0x00, 0xF0, 0, 0, 0])  # 0x1019 := 240
        assert len(writes) == 5  # the PDO mapping was already as needed: not written
        assert sdo[-1] == bytes([0x40, 0x61, 0x60, 0x00, 0, 0, 0, 0])  # read 0x6061
        assert drv.identities[0] is None and drv.pdos_written == 0
        # cyclic: 8 RPDOs then SYNC, disabled drives get "disable voltage" and zero torque
        assert peer.sent(p.RPDO1 + 3)[-1] == bytes([0x00, 0x00, 0x00, 0x00])
        order = [a for _, a, _ in peer.rx if a in (p.SYNC, p.RPDO1 + 8)]
        assert order[:2] == [p.RPDO1 + 8, p.SYNC]


def test_cia402_enable_sequence_follows_transition_table(seed):
    with configured(seed) as (drv, peer, _):
        drv.activate()
        assert drv.lifecycle is Lifecycle.ACTIVE
        cws = [struct.unpack("<H", d[:2])[0] for d in peer.sent(p.RPDO1 + 5)]
        # disable voltage while configuring, then transitions 2 (0x06), 3 (0x07), 4 (0x0F)
        steps = [cw for i, cw in enumerate(cws) if i == 0 or cw != cws[i - 1]]
        assert steps == [0x0000, 0x0006, 0x0007, 0x000F]
        # torque: 1.3 N·m with rated torque 5 N·m (seed000 drives) is 260 per-mille
        drv.write(peer.t, np.full(8, 1.3))
        peer.pump()
        assert peer.sent(p.RPDO1 + 1)[-1] == struct.pack("<Hh", 0x000F, 260)


def cycles(drv, peer, n: int = 1) -> None:
    """``n`` control periods of 2 ms: read, write zero torques, let the drives answer."""
    for _ in range(n):
        drv.read(peer.t)
        drv.write(peer.t, np.zeros(8))
        peer.wait(0.002)


def test_cia402_sync_counter_runs_to_its_overflow(seed):
    """The SYNC carries its counter, 1 … 240 then 1 again (CiA 301, 0x1019 := 240)."""
    drv, peer = make(seed, Cia402Script(range(1, 9)))
    with drv:
        drv.configure()
        cycles(drv, peer, 250)
        counts = [d[0] for d in peer.sent(p.SYNC)]
        assert all(len(d) == 1 for d in peer.sent(p.SYNC))
        assert counts[:3] == [1, 2, 3]
        assert counts[239:242] == [240, 1, 2]
        assert all(b == a % 240 + 1 for a, b in itertools.pairwise(counts))


def test_cia402_write_is_stamped_at_its_sync(seed):
    """The drives take a write's frames at its SYNC: ``sent_at`` (where ``cdprctl run --sim``
    handles them) is the SYNC's instant even when the process is held up after it (here 1 ms
    while it sends its heartbeat). Stamped when the write returned, the simulated SYNC came
    that much after the instant its targets were carried to."""
    drv, peer = make(seed, Cia402Script(range(1, 9)))
    heartbeat = p.HEARTBEAT + seed.drives.controller_node_id
    with drv:
        drv.configure()
        send, held = drv._send, []

        def held_up(b, msg):
            sent = send(b, msg)
            if msg.arbitration_id == heartbeat:
                peer.t += 0.001
                held.append(peer.t)
            return sent

        drv._send = held_up
        for _ in range(120):
            drv.read(peer.t)
            n = len(held)
            drv.write(peer.t, np.zeros(8))
            if len(held) > n:
                assert drv.sent_at == drv.sync.last == pytest.approx(peer.t - 0.001)
            else:
                assert drv.sent_at == drv.sync.last == peer.t
            peer.wait(0.002)
        assert len(held) >= 2


def test_cia402_position_units_and_wrap(seed):
    script = Cia402Script(range(1, 9))
    drv, peer = make(seed, script)
    cpr = seed.cables[0].winch.encoder_counts_per_rev
    script.position[1] = 2**31 - 100  # from the first frame on: a step would be implausible
    with drv:
        drv.configure()
        cycles(drv, peer, 2)
        before = drv.states.position[0]
        script.position[1] = -(2**31) + 100  # +200 counts through the 32-bit wrap
        cycles(drv, peer)
        drv.read(peer.t)
        assert drv.states.position[0] - before == pytest.approx(200 * 2 * math.pi / cpr)
        # velocity derived between the two SYNCs (0.002 s apart)
        assert drv.states.velocity[0] == pytest.approx(200 * 2 * math.pi / cpr / 0.002)


def test_a_position_step_no_motor_can_make_is_dropped_then_reported(seed):
    """A corrupted position (a flipped high bit) is dropped like a lost frame and counted;
    if every later frame disagrees the same way (a failing encoder), the feedback timeout
    names the implausible jumps."""
    with configured(seed) as (drv, peer, script):
        cycles(drv, peer, 2)
        before = drv.states.position[0]
        script.position[1] += 1 << 24  # 256 motor turns in 2 ms
        cycles(drv, peer)
        drv.read(peer.t)
        assert drv.states.position[0] == before  # dropped
        assert drv.stats.implausible_frames >= 1
        for _ in range(round(drv.config.feedback_timeout / 0.002) + 2):
            drv.write(peer.t, np.zeros(8))
            peer.wait(0.002)
            drv.read(peer.t)
        assert drv.lifecycle is Lifecycle.ERROR
        assert "no motor can make" in str(drv.error)


def over_current_on_node_4(drv, peer, script) -> None:
    """Configured and enabled, then node 4 sends EMCY 0x2310 (over-current) and faults; three
    periods later."""
    drv.configure()
    drv.activate()
    script.emcy[4] = 0x2310
    cycles(drv, peer, 3)


def test_cia402_emcy_is_a_typed_fault_and_reset_recovers(seed):
    script = Cia402Script(range(1, 9))
    drv, peer = make(seed, script)
    with drv:
        over_current_on_node_4(drv, peer, script)
        assert drv.lifecycle is Lifecycle.ERROR
        assert isinstance(drv.error, DriveFaultError)
        assert drv.error.code == 0x2310 and drv.error.cable == 3
        assert "over-current" in str(drv.error)
        drv.recover()
        assert drv.lifecycle is Lifecycle.INACTIVE
        cws = [struct.unpack("<H", d[:2])[0] for d in peer.sent(p.RPDO1 + 4)]
        i = cws.index(0x0080)  # fault reset, transition 15, after a 0x0000: a rising edge
        assert cws[i - 1] == 0x0000


def test_cia402_missing_feedback_tolerated_then_fault(seed):
    with configured(seed) as (drv, peer, script):
        script.drop_tpdo.add(2)
        for k in range(round(seed.drives.feedback_timeout / 0.002) + 2):
            cycles(drv, peer)
            if k == 1:
                assert drv.lifecycle is Lifecycle.INACTIVE
                assert drv.states.feedback_age[1] > 0.002  # one TPDO missed: reported
        assert drv.lifecycle is Lifecycle.ERROR
        assert isinstance(drv.error, DriverTimeoutError) and drv.error.cable == 1


def test_cia402_lost_heartbeat(seed):
    with configured(seed) as (drv, peer, script):
        script.silent.add(6)
        t_end = peer.t + seed.drives.heartbeat_timeout + 0.05
        while peer.t < t_end and drv.lifecycle is Lifecycle.INACTIVE:
            cycles(drv, peer)
        assert isinstance(drv.error, DriverTimeoutError)
        assert drv.error.cable == 5


# CiA 402 Table 30 written out: a statusword of each power state (bits 0-3, 5, 6; the others
# set where a drive may set them) and what the control side must see of it
STATUSWORD_SEEN_AS = [
    (0x0000, DriveState.DISABLED),  # not ready to switch on: booting, the brake holds
    (0x0250, DriveState.DISABLED),  # switch on disabled, voltage and remote bits set
    (0x0231, DriveState.READY),  # ready to switch on
    (0x0233, DriveState.READY),  # switched on
    (0x0637, DriveState.ENABLED),  # operation enabled, target reached
    (0x0017, DriveState.QUICK_STOP),  # quick stop active
    (0x001F, DriveState.FAULT),  # fault reaction active
    (0x0218, DriveState.FAULT),  # fault
]


@pytest.mark.parametrize("sw, seen", STATUSWORD_SEEN_AS, ids=lambda v: f"{v}")
def test_every_power_state_reaches_the_control_side_as_its_drive_state(seed, sw, seen):
    """A statusword of each CiA 402 power state, from one drive, through the cyclic decoding
    tables: the control side's drive state of that cable, the others untouched."""
    with configured(seed) as (drv, peer, script):
        script.statusword[3] = sw
        cycles(drv, peer, 2)
        drv.read(peer.t)
        assert DriveState(drv.states.state[2]) is seen
        assert set(drv.states.state[[0, 1, 3, 4, 5, 6, 7]]) == {DriveState.DISABLED}


def test_cia402_ignores_foreign_and_malformed_frames(seed):
    with configured(seed) as (drv, peer, _):
        junk = [
            frame(0x123, b"\1\2"),
            frame(p.TPDO1 + 1, b"\0\0"),
            can.Message(arbitration_id=0x181, data=b"\0" * 8, is_extended_id=True),
        ]
        for m in junk:
            peer.bus.send(m)
        drv.read(peer.t + 0.001)
        assert drv.lifecycle is Lifecycle.INACTIVE
        assert drv.stats.frames_ignored >= 3


class ODriveScript:
    def __init__(self, nodes):
        self.state = {n: po.AxisState.IDLE for n in nodes}
        self.error = {n: 0 for n in nodes}
        self.mode = {n: 0 for n in nodes}
        self.torque = {n: 0.0 for n in nodes}

    @staticmethod
    def velocity(n: int) -> float:
        """turns/s axis ``n`` reports: signed, a different value per axis"""
        return 0.5 * n - 2.25

    @staticmethod
    def torque_estimate(n: int) -> float:
        """N·m axis ``n`` reports applying"""
        return 0.03 * n - 0.1

    def __call__(self, msg, t):
        node, cmd = msg.arbitration_id >> 5, msg.arbitration_id & 0x1F
        data = bytes(msg.data)
        if cmd == po.SET_CONTROLLER_MODE:
            self.mode[node] = po.MODE_STRUCT.unpack(data)[0]
        elif cmd == po.SET_AXIS_STATE:
            self.state[node] = po.AxisState(po.U32_STRUCT.unpack(data)[0])
        elif cmd == po.SET_INPUT_TORQUE:
            self.torque[node] = po.TORQUE_STRUCT.unpack(data)[0]
            if node == 8:  # the last axis of the cycle: stream everyone's feedback
                out = []
                for n in self.state:
                    # ODrive's CAN Simple layouts, written out: position (turns) and
                    # velocity (turns/s) as two float32; torque target and estimate (N·m)
                    out.append(
                        frame(
                            po.arbitration_id(n, po.GET_ENCODER_ESTIMATES),
                            struct.pack("<ff", 0.25 * n, self.velocity(n)),
                        )
                    )
                    out.append(
                        frame(
                            po.arbitration_id(n, po.GET_TORQUES),
                            struct.pack("<ff", self.torque[n], self.torque_estimate(n)),
                        )
                    )
                    out.append(
                        frame(
                            po.arbitration_id(n, po.HEARTBEAT),
                            po.HEARTBEAT_STRUCT.pack(self.error[n], int(self.state[n]), 0, 0),
                        )
                    )
                return out
        elif cmd == po.CLEAR_ERRORS:
            self.error[node] = 0
        return []


def test_odrive_frames(seed):
    script = ODriveScript(range(1, 9))
    drv, peer = make(seed, script, "odrive")
    with drv:
        drv.configure()
        assert peer.sent(po.arbitration_id(3, po.SET_CONTROLLER_MODE))[0] == struct.pack(
            "<II", 1, 1
        )  # torque control, passthrough
        drv.activate()
        assert peer.sent(po.arbitration_id(3, po.SET_AXIS_STATE))[-1] == struct.pack("<I", 8)
        assert drv.states.position[2] == pytest.approx(0.75 * 2 * math.pi)  # turns → rad
        drv.write(peer.t, np.zeros(8))  # a cycle: every axis streams its estimates
        peer.wait(0.002)
        drv.read(peer.t)
        for c, n in enumerate(range(1, 9)):
            # turns/s → rad/s; N·m as sent (the estimate, not the target)
            assert drv.states.velocity[c] == pytest.approx(script.velocity(n) * 2 * math.pi)
            assert drv.states.torque[c] == pytest.approx(script.torque_estimate(n), abs=1e-6)
        drv.write(peer.t, np.full(8, 0.5))
        peer.pump()
        assert peer.sent(po.arbitration_id(2, po.SET_INPUT_TORQUE))[-1] == struct.pack("<f", 0.5)
        script.error[7] = 0x00002000  # motor over-temperature
        for _ in range(2):
            drv.write(peer.t, np.zeros(8))
            peer.wait(0.002)
            drv.read(peer.t)
        assert isinstance(drv.error, DriveFaultError)
        assert "motor over-temperature" in str(drv.error)
        drv.recover()
        assert drv.lifecycle is Lifecycle.INACTIVE
        assert peer.sent(po.arbitration_id(7, po.CLEAR_ERRORS))


def test_capabilities_judge_the_profile_the_modes_and_the_rated_torque_by_their_bits():
    """What ``drives scan`` and the set-up read, judged bit by bit: the device type's low 16
    bits are the profile (402 with any additional information runs; 401, 403, 406 do not,
    named); 0x6502's csp bit 7 and cst bit 9, each alone; the rated torque within 1 % of the
    config's."""
    from drivers.cia402.capabilities import Capabilities, rated_torque_problem

    def caps(device_type: int | None = None, modes: int | None = None) -> Capabilities:
        return Capabilities(None, device_type, modes, None)

    assert caps(0x00020192).can_run(p.MODE_CSP) is None  # 402, a servo drive
    for profile in (401, 403, 406):
        why = caps(0x00010000 | profile).can_run(p.MODE_CSP)
        assert why is not None and f"is profile {profile}, not CiA 402" in why
    csp, cst, csv = 1 << 7, 1 << 9, 1 << 8
    assert caps(modes=csp).modes_text() == "0x6502 = 0x00000080 (csp)"
    assert caps(modes=cst).modes_text() == "0x6502 = 0x00000200 (cst)"
    assert caps(modes=csp | cst).modes_text() == "0x6502 = 0x00000280 (csp, cst)"
    assert caps(modes=csv).modes_text() == "0x6502 = 0x00000100 (no csp, no cst)"
    assert caps(modes=csp).can_run(p.MODE_CSP) is None
    why = caps(modes=csv | csp).can_run(p.MODE_CST)
    assert why is not None and "lacks cyclic synchronous torque (bit 9" in why
    assert rated_torque_problem(None, 1000.0) is None
    for rated in (1010, 990, 1009, 991):  # within 1 %, the bound included
        assert rated_torque_problem(rated, 1000.0) is None
    assert "rated torque 0x6076 is 1011 mN·m, the config says 1000" in (
        rated_torque_problem(1011, 1000.0) or "")  # fmt: skip
    assert "(not set:" in (rated_torque_problem(0, 1000.0) or "")


@pytest.mark.parametrize("source", ["pdo", "derived"])
def test_the_velocity_comes_from_where_the_config_says(tmp_path, source, monkeypatch):
    """`[drives] velocity_source`: "pdo" takes each drive's own velocity (0x606C in TPDO2,
    counts/s → rad/s), "derived" differentiates the positions: a drive made to report 12345
    counts/s while its drum is at rest tells them apart."""
    from sim_backend.drives.axis import Cia402Axis
    from sim_backend.network import LockStep

    f = tmp_path / "v.toml"
    f.write_text(f'base = "{CONFIG / "rowc.toml"}"\n[drives]\nvelocity_source = "{source}"\n')
    monkeypatch.setattr(Cia402Axis, "velocity_counts", lambda self: 12345)
    with LockStep(load_robot(f), period=0.004) as ls:
        ls.driver.configure()
        for _ in range(5):
            ls.cycle(np.zeros(8))
        got = ls.driver.read(ls.net.time).velocity
        reported = 12345 * 2 * math.pi / ls.net.drives[0].axis.cpr  # rad/s
        if source == "pdo":
            np.testing.assert_allclose(got, reported, rtol=1e-12)
        else:
            np.testing.assert_allclose(got, 0.0, atol=1e-9)  # the brakes hold every drum


def test_each_drives_heartbeat_is_taken_as_its_heartbeat():
    """The drives' heartbeats (0x700 + node, producer time set at set-up) mark each drive
    alive with the time they came, and tell its NMT state (operational: 0x05)."""
    from sim_backend.network import LockStep

    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        ls.driver.configure()
        for _ in range(100):  # 0.4 s: several heartbeat periods
            ls.cycle(np.zeros(8))
        ls.driver.read(ls.net.time)
        last = ls.driver.liveness.last_hb
        assert np.all(ls.net.time - last < 0.25), (ls.net.time, last)
        assert list(ls.driver.feedback.nmt_state) == [0x05] * 8


def test_an_implausible_position_is_counted_against_its_drive_alone():
    """A position step no motor can make in a period (10^7 counts: an encoder or a frame gone
    wrong) is dropped and counted for that drive — what the liveness error reports — and for
    no other."""
    from sim_backend.network import LockStep

    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        ls.driver.configure()
        for _ in range(5):
            ls.cycle(np.zeros(8))
        ls.net.drives[3].axis.encoder_offset += 10**7
        ls.cycle(np.zeros(8))
        ls.cycle(np.zeros(8))
        assert list(ls.driver.liveness.implausible) == [0, 0, 0, 1, 0, 0, 0, 0]


@contextlib.contextmanager
def active_rowc():
    """rowc's CiA 402 drives in lock-step (250 Hz), configured and enabled: (the lock-step,
    the positions they stand at, rad)."""
    from sim_backend.network import LockStep

    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        ls.driver.configure()
        ls.driver.activate()
        yield ls, ls.driver.read(ls.net.time).position.copy()


def test_a_cycle_held_up_before_its_send_carries_its_targets_to_the_send():
    """Position mode, targets moving at 2.5 rad/s: a cycle whose send comes 3 ms after its
    time (the VM took the CPU mid-cycle) sends its targets for the send's instant — 3 ms on at
    their rate, 0.0075 rad, 78 counts at rowc's 65536 a turn — not for the instant long
    past."""

    def sent_target(held: float) -> int:
        with active_rowc() as (ls, base):
            d = ls.driver
            for k in range(3):
                t = ls.net.time  # the cycle's time
                d.read(t)
                if k == 2:
                    ls.net.advance(held)  # held up: the send's clock is later
                d.write(t, np.zeros(8), targets=base + 0.01 * k)
                ls.net.advance(0.004 - (held if k == 2 else 0.0))
            return int(ls.net.drives[0].axis.target_counts)

    moved = sent_target(0.003) - sent_target(0.0)
    assert moved == pytest.approx(0.0075 * 65536 / (2 * math.pi), abs=2.0), moved
