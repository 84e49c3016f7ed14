"""The simulated CiA 402 drive's own reactions, in lock-step through our driver: the torque it
reports is the one it applies (after 0x6072), and losing the controller ends where 0x6007
says (CiA 402 §6.4.1)."""

from __future__ import annotations

import dataclasses
import itertools
import math
import uuid

import can
import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode

from cdprctl.robot_file import load_robot
from drivers.cia402 import protocol as p
from sim_backend.network import LockStep


def enabled_rig(config: str, torque_mode: bool = False) -> LockStep:
    model = load_robot(CONFIG / config)
    if torque_mode:
        model = in_torque_mode(model)
    rig = LockStep(model, period=model.control.period)
    rig.driver.configure()
    rig.driver.activate()
    return rig


def cycles(rig: LockStep, torques: np.ndarray, n: int) -> None:
    for _ in range(n):
        t = rig.net.time
        rig.driver.read(t)
        rig.driver.write(t, torques, targets=rig.driver.states.position.copy())
        rig.net.advance(rig.period)
    rig.driver.read(rig.net.time)


def test_torque_actual_is_the_torque_applied_after_0x6072():
    """Torque mode (seed000): 0x6072 := half the winch's limit on drive 1, the full limit
    commanded: the drive applies half and reports half (it reported the target)."""
    with enabled_rig("seed000.toml", torque_mode=True) as rig:
        drive = rig.net.drives[0]
        limit = rig.model.cables[0].winch.torque_limit
        half_pm = round(0.5 * limit / drive.axis.rated_torque * 1000)
        reply = drive.on_sdo(p.sdo_download(p.OD_MAX_TORQUE, 0, half_pm, 2))
        assert reply is not None and reply.data[0] == 0x60
        torques = np.full(rig.model.n_cables, 0.9 * limit)
        cycles(rig, torques, 5)
        assert rig.plant.motor_torque[0] == pytest.approx(0.5 * limit, rel=1e-3)
        assert rig.plant.motor_torque[1] == pytest.approx(0.9 * limit, rel=1e-3)
        assert rig.driver.states.torque[0] == pytest.approx(0.5 * limit, rel=0.01)
        assert rig.driver.states.torque[1] == pytest.approx(0.9 * limit, rel=0.01)


@pytest.mark.parametrize(
    ("option", "state", "emcy"),
    [
        (0, p.PowerState.OPERATION_ENABLED, False),
        (1, p.PowerState.FAULT, True),
        (2, p.PowerState.SWITCH_ON_DISABLED, True),
        (3, p.PowerState.QUICK_STOP_ACTIVE, True),
        (0xFFFF, p.PowerState.FAULT, True),  # -1 as INTEGER16: manufacturer-specific
    ],
)
def test_the_abort_connection_option_decides_the_reaction(option, state, emcy):
    """The controller goes silent: after the drives' communication timeout each reacts as
    its 0x6007 says — 1 (fault signal) ends in FAULT, not in "disable voltage"; a negative
    (manufacturer-specific) code reacts too, as a fault (no code of ours is "no action" but
    0)."""
    with enabled_rig("rowc.toml") as rig:
        drive = rig.net.drives[3]
        assert drive.od[(p.OD_ABORT_CONNECTION, 0)] == 3  # the driver's choice: quick stop
        reply = drive.on_sdo(p.sdo_download(p.OD_ABORT_CONNECTION, 0, option, 2))
        assert reply is not None and reply.data[0] == 0x60
        hold = rig.plant.drum_ratio * rig.plant.tension
        cycles(rig, hold, 10)
        assert drive.axis.state is p.PowerState.OPERATION_ENABLED
        frames: list[int] = []
        for _ in range(round(3 * rig.model.drives.comm_timeout / rig.period)):
            rig.net.advance(rig.period)  # no frame from the controller
            while (msg := rig.driver.buses[rig.net.bus_index_of(3)].recv(0)) is not None:
                if msg.arbitration_id == p.EMCY + drive.node_id:
                    frames.append(p.EMCY_STRUCT.unpack(msg.data)[0])
        assert drive.axis.state is state
        assert (0x8130 in frames) is emcy
        if option == 1:
            assert drive.axis.fault_code == 0x8130


def test_an_abort_connection_option_beyond_the_standard_is_refused():
    model = load_robot(CONFIG / "rowc.toml")
    with LockStep(model, period=model.control.period) as rig:
        reply = rig.net.drives[0].on_sdo(p.sdo_download(p.OD_ABORT_CONNECTION, 0, 7, 2))
        assert reply is not None and reply.data[0] == 0x80
        assert int.from_bytes(reply.data[4:8], "little") == 0x06090031


def abort_code(reply) -> int | None:
    assert reply is not None
    return int.from_bytes(reply.data[4:8], "little") if reply.data[0] == 0x80 else None


def test_the_mapping_changes_only_the_standard_way():
    """CiA 301's procedure and its abort codes: not in OPERATIONAL; not while the PDO is
    valid; entries only while the count is 0; an object that cannot be mapped (not writable
    into an RPDO, or with another length); more than 64 bits."""
    model = load_robot(CONFIG / "rowc.toml")
    with LockStep(model, period=model.control.period) as rig:
        d = rig.net.drives[0]

        def write(index, sub, value, size):
            return abort_code(d.on_sdo(p.sdo_download(index, sub, value, size)))

        d.on_nmt(p.NMT_START)
        assert write(0x1600, 0, 0, 1) == 0x08000022  # OPERATIONAL
        d.on_nmt(p.NMT_PRE_OPERATIONAL)
        assert write(0x1600, 0, 0, 1) == 0x06010000  # the PDO is still valid
        assert write(0x1400, 1, 0x80000000 | (0x200 + d.node_id), 4) is None
        assert write(0x1600, 1, 0x60400010, 4) == 0x06010000  # count not 0
        assert write(0x1600, 0, 0, 1) is None
        assert write(0x1600, 1, 0x60410010, 4) == 0x06040041  # statusword: not writable
        assert write(0x1600, 1, 0x10170010, 4) == 0x06040041  # not mappable
        assert write(0x1600, 1, 0x607A0010, 4) == 0x06040041  # 0x607A is 32 bits
        for k, entry in enumerate((0x607A0020, 0x607A0020, 0x60400010), 1):
            assert write(0x1600, k, entry, 4) is None
        assert write(0x1600, 0, 3, 1) == 0x06040042  # 80 bits
        assert write(0x1600, 0, 2, 1) is None
        assert write(0x1400, 1, 0x200 + d.node_id, 4) is None  # valid again
        assert d.rpdo_owners[0x200 + d.node_id] is d


def test_static_mapping_refuses_a_drive_that_differs():
    """``pdo_mapping = "static"``: position mode needs RPDO1 = controlword, target position,
    torque offset; the simulated drive's default is the torque mode's. The driver refuses,
    naming the drive, the object, what it expected and what it found."""
    import dataclasses

    from drivers.errors import DriverInitializationError

    model = load_robot(CONFIG / "rowc.toml")
    model = dataclasses.replace(
        model, drives=dataclasses.replace(model.drives, pdo_mapping="static")
    )
    with LockStep(model, period=model.control.period) as rig:
        with pytest.raises(DriverInitializationError) as err:
            rig.driver.configure()
        text = str(err.value)
        assert "node 1" in text and "RPDO1" in text and "0x1600" in text
        assert "expected [0x6040:00 controlword (16 bit), 0x607A:00 target position" in text
        assert "found [0x6040:00 controlword (16 bit), 0x6071:00 target torque" in text


def test_configure_writes_the_mapping_and_reads_it_back():
    """The default ``pdo_mapping = "configure"``: rowc's drives in position mode get RPDO1
    remapped (8 drives, one PDO each: TPDO1 already fits), read back, and the drives then
    run in position mode; the identities are read."""
    with enabled_rig("rowc.toml") as rig:
        assert rig.driver.pdos_written == rig.model.n_cables
        for c, d in enumerate(rig.net.drives):
            assert d.od[(0x1600, 0)] == 3 and d.od[(0x1600, 2)] == 0x607A0020
            assert rig.driver.identities[c] == {
                "vendor_id": 0, "product_code": 0x402, "revision": 0x10000,
                "serial": 0x53494D00 + d.node_id,
            }  # fmt: skip
        cycles(rig, rig.plant.drum_ratio * rig.plant.tension, 20)
        assert all(d.axis.state is p.PowerState.OPERATION_ENABLED for d in rig.net.drives)
        assert rig.driver.lifecycle.value == "active"


def dcf_with(tmp_path, values: dict[str, int], extra: str = "") -> str:
    """The shipped EDS as a DCF: ParameterValue lines in the sections named ("6065",
    "1800sub3"), and ``extra`` sections."""
    from sim_backend.drives.dictionary import EDS

    text = EDS.read_text()
    for section, value in values.items():
        head = f"[{section}]\n"
        assert head in text, section
        text = text.replace(head, f"{head}ParameterValue=0x{value:X}\n")
    path = tmp_path / "winch.dcf"
    path.write_text(text + extra)
    return str(path)


def with_dcf(model, path):
    import dataclasses

    buses = tuple(
        dataclasses.replace(b, dcf=(path,) * len(b.node_ids)) for b in model.drives.buses
    )
    return dataclasses.replace(model, drives=dataclasses.replace(model.drives, buses=buses))


def test_a_dcfs_parameter_values_are_written_at_set_up(tmp_path):
    """``[[drives.buses]] dcf``: its writable ParameterValues go to each drive by SDO before
    cdprctl's own settings (a read-only one, 0x1000, is skipped; 0x1017, which cdprctl sets
    too, ends as cdprctl's)."""
    path = dcf_with(tmp_path, {"6065": 5000, "1800sub3": 7, "1000": 0x1234, "1017": 999})
    model = with_dcf(in_torque_mode(load_robot(CONFIG / "seed000.toml")), path)
    with LockStep(model, period=model.control.period) as rig:
        rig.driver.configure()
        for d in rig.net.drives:
            assert d.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] == 5000
            assert d.od[(0x1800, 3)] == 7
            assert d.od[(0x1000, 0)] == 0x00020192
            assert d.od[(p.OD_PRODUCER_HEARTBEAT, 0)] == 100  # cdprctl's: timeout / 5


def test_a_dcf_value_the_drive_refuses_stops_the_set_up_by_name(tmp_path):
    from drivers.errors import DriverInitializationError

    path = dcf_with(tmp_path, {"6007": 9})  # beyond CiA 402's codes: the drive aborts
    model = with_dcf(in_torque_mode(load_robot(CONFIG / "seed000.toml")), path)
    with LockStep(model, period=model.control.period) as rig:
        with pytest.raises(DriverInitializationError) as err:
            rig.driver.configure()
        assert "refused 0x6007:00 := 9 from" in str(err.value) and "winch.dcf" in str(err.value)
        assert "0x06090031" in str(err.value)


def test_the_realtime_simulator_says_ready_after_its_first_physics_step(monkeypatch):
    """``cdprctl sim`` prints "ready" only once its physics has stepped (its kernels compiled):
    on a cold cache the drives stood deaf for ~15 s after "ready"."""
    import uuid

    from sim_backend import realtime
    from sim_backend.network import SimNetwork

    steps: list[float] = []
    advance = SimNetwork.advance

    def counting(self, dt, first=None):
        steps.append(dt)
        return advance(self, dt, first)

    monkeypatch.setattr(SimNetwork, "advance", counting)
    said: list[int] = []

    def printed(text, **_):
        if "ready" in text:
            said.append(len(steps))

    model = load_robot(CONFIG / "rowc.toml")
    net = realtime.run_realtime(
        model, {"interface": "inprocess", "channel": f"rt-{uuid.uuid4().hex}"},
        duration=0.01, print_fn=printed,
    )  # fmt: skip
    net.close()
    assert said and said[0] >= 1


def test_a_following_error_window_of_all_ones_switches_the_check_off():
    """CiA 402 §6.5.7 (0x6065): 0xFFFFFFFF switches the drive's following-error monitoring
    off, any other value is a window in counts. The frames are written out byte by byte here;
    the driver never sends the all-ones value, even for a window beyond 32 bits of counts."""
    model = load_robot(CONFIG / "rowc.toml")
    huge = dataclasses.replace(model.drives, following_error_window=1e9)  # m of cable
    with enabled_rig("rowc.toml") as rig:
        drive, servo = rig.net.drives[0], rig.plant.servo
        assert 0 < servo.window[0] < 1.0  # rad: the driver's window
        reply = drive.on_sdo(bytes([0x23, 0x65, 0x60, 0x00, 0xFF, 0xFF, 0xFF, 0xFF]))
        assert reply is not None and reply.data[0] == 0x60
        assert servo.window[0] == math.inf
        drive.on_sdo(bytes([0x23, 0x65, 0x60, 0x00, 0xFE, 0xFF, 0xFF, 0xFF]))
        assert servo.window[0] == pytest.approx(0xFFFFFFFE * 2 * math.pi / drive.axis.cpr)
    rig = LockStep(dataclasses.replace(model, drives=huge), period=model.control.period)
    with rig:
        rig.driver.configure()
        assert rig.net.drives[0].axis.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] == 0xFFFFFFFE
        assert math.isfinite(rig.plant.servo.window[0])


class RawPeer:
    """A plain python-can bus beside the simulated drives (lock-step, 1 ms steps): frames
    written out byte by byte, what the drives send collected with its instant."""

    def __init__(self) -> None:
        from sim_backend.network import SimNetwork
        from sim_backend.plant import CdprPlant

        channel = f"raw-{uuid.uuid4().hex}"
        model = load_robot(CONFIG / "rowc.toml")
        self.net = SimNetwork(model, CdprPlant(model), {"interface": "inprocess",
                                                        "channel": channel})  # fmt: skip
        self.bus = can.Bus(interface="inprocess", channel=channel)
        self.got: list[tuple[float, int, bytes]] = []
        self.extended: set[int] = set()  # the identifiers that came as extended frames

    def send(self, arb: int, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=arb, data=data, is_extended_id=False))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / 0.001)):
            self.net.advance(0.001)
            while (msg := self.bus.recv(0)) is not None:
                self.got.append((self.net.time, msg.arbitration_id, bytes(msg.data)))
                if msg.is_extended_id:
                    self.extended.add(msg.arbitration_id)

    def heartbeats(self, node: int, since: float = -1.0) -> list[tuple[float, int]]:
        return [(t, d[0]) for t, a, d in self.got if a == 0x700 + node and t > since]

    def sdo(self, node: int, request: bytes) -> bytes | None:
        before = len(self.got)
        self.send(0x600 + node, request)
        self.run(0.002)
        return next((d for _, a, d in self.got[before:] if a == 0x580 + node), None)

    def close(self) -> None:
        self.bus.shutdown()
        self.net.close()


def test_heartbeats_at_the_producer_time_through_nmt_states_and_resets():
    """CiA 301: a heartbeat (0x700 + node, one byte: the NMT state) every 0x1017 ms, none at
    0; NMT stop (no SDO answered), pre-operational, an unknown command ignored; reset
    communication restores 0x1000-0x1FFF and keeps 0x6007, reset node restores both; each
    reset ends with the boot-up message and the heartbeat goes on."""
    peer = RawPeer()
    try:
        peer.run(0.3)
        assert peer.heartbeats(1) == []  # 0x1017 = 0 by default: none
        assert peer.sdo(1, bytes([0x2B, 0x17, 0x10, 0, 0xD0, 0x07, 0, 0]))[0] == 0x60  # 2 s
        assert peer.sdo(1, bytes([0x2B, 0x07, 0x60, 0, 2, 0, 0, 0]))[0] == 0x60  # 0x6007 := 2
        peer.run(4.5)
        beats = peer.heartbeats(1)
        assert {s for _, s in beats} == {0x7F}  # pre-operational
        gaps = {round(b[0] - a[0], 4) for a, b in itertools.pairwise(beats)}
        assert gaps == {2.0} and len(beats) == 3  # to the ms
        assert peer.heartbeats(2) == []
        assert peer.sdo(1, bytes([0x2B, 0x17, 0x10, 0, 50, 0, 0, 0]))[0] == 0x60  # 50 ms
        peer.run(0.2)
        for command, state in ((0x01, 0x05), (0x03, 0x05), (0x00, 0x05), (0x02, 0x04),
                               (0x83, 0x04), (0x80, 0x7F), (0x00, 0x7F)):  # fmt: skip
            t = peer.net.time
            peer.send(0x000, bytes([command, 1]))
            peer.run(0.12)
            assert {s for _, s in peer.heartbeats(1, since=t + 0.002)} == {state}, command
            if state == 0x04:  # stopped: no SDO answered
                assert peer.sdo(1, bytes([0x40, 0x17, 0x10, 0, 0, 0, 0, 0])) is None
        upload = bytes([0x40, 0x07, 0x60, 0, 0, 0, 0, 0])
        for command, kept in ((0x82, 2), (0x81, None)):  # communication, then node
            t = peer.net.time
            peer.send(0x000, bytes([command, 1]))
            peer.run(0.01)
            assert peer.heartbeats(1, since=t)[0][1] == 0x00  # boot-up
            assert peer.sdo(1, bytes([0x40, 0x17, 0x10, 0, 0, 0, 0, 0]))[4] == 0  # default
            value = peer.sdo(1, upload)[4]
            assert value == kept if kept is not None else value != 2
            assert peer.sdo(1, bytes([0x2B, 0x17, 0x10, 0, 20, 0, 0, 0]))[0] == 0x60
            t = peer.net.time
            peer.run(0.2)
            assert 9 <= len(peer.heartbeats(1, since=t)) <= 11  # the heartbeat goes on
        assert peer.sdo(1, bytes([0x2B, 0x17, 0x10, 0, 1, 0, 0, 0]))[0] == 0x60  # 1 ms, the least
        t = peer.net.time
        peer.run(0.02)
        assert 18 <= len(peer.heartbeats(1, since=t)) <= 21
        assert peer.extended == set()  # CiA 301's identifiers are 11-bit: standard frames
    finally:
        peer.close()


def test_what_the_simulated_drive_answers_and_what_it_ignores():
    """An SDO request of 7 bytes is not one (no answer); in PRE-OPERATIONAL a SYNC gets no
    TPDO; an EMCY is a standard frame 0x80 + node: the code, the error register's generic bit,
    five bytes 0; a value that equals a mode number written to another object is no mode
    (0x6007 := 1, 0x6065 := 1 taken although 0x6502 has no mode 1), and only 0x6076 changes
    the rated torque; 0x6072's default is the winch's limit in per mille of the rated torque."""
    peer = RawPeer()
    try:
        model = peer.net.model
        drive = peer.net.nodes[0][1]
        assert peer.sdo(1, bytes([0x40, 0x18, 0x10, 1, 0, 0, 0])) is None
        before = len(peer.got)
        peer.send(0x080, b"")  # SYNC, the node pre-operational
        peer.run(0.003)
        assert not [a for _, a, _ in peer.got[before:] if 0x180 <= a < 0x500]
        emcy = drive.inject_fault(0x2310)
        assert emcy.arbitration_id == 0x81 and not emcy.is_extended_id
        assert bytes(emcy.data) == bytes([0x10, 0x23, 0x01, 0, 0, 0, 0, 0])
        rated = drive.axis.rated_torque
        stored = peer.sdo(1, bytes([0x40, 0x76, 0x60, 0, 0, 0, 0, 0]))  # 0x6076, mN·m
        assert int.from_bytes(stored[4:8], "little") == round(model.drives.rated_torque * 1000)
        for index in (0x6007, 0x6065):
            reply = peer.sdo(1, bytes([0x2B if index == 0x6007 else 0x23, index & 0xFF,
                                       index >> 8, 0, 1, 0, 0, 0]))  # fmt: skip
            assert reply is not None and reply[0] == 0x60, hex(index)
        assert peer.sdo(1, bytes([0x23, 0x7A, 0x60, 0, 5, 0, 0, 0]))[0] == 0x60  # 0x607A := 5
        assert drive.axis.rated_torque == rated
        mode = peer.sdo(1, bytes([0x40, 0x61, 0x60, 0, 0, 0, 0, 0]))
        assert mode[4] != 1  # 0x6061 follows 0x6060 alone, not a 1 written elsewhere
        for value, taken in ((1, 0.001), (2500, 2.5), (0, 2.5)):  # mN·m; 0 is no rated torque
            reply = peer.sdo(1, bytes([0x23, 0x76, 0x60, 0, *value.to_bytes(4, "little")]))
            assert reply[0] == 0x60 and drive.axis.rated_torque == taken, value
        upload = peer.sdo(1, bytes([0x40, 0x72, 0x60, 0, 0, 0, 0, 0]))
        winch = model.cables[0].winch
        want = min(0xFFFF, round(winch.torque_limit / model.drives.rated_torque * 1000))
        assert int.from_bytes(upload[4:6], "little") == want
    finally:
        peer.close()


def test_the_torque_limit_object_saturates_at_its_type():
    """0x6072 is UNSIGNED16 per mille of the rated torque: a winch limit beyond 65.535 × rated
    stores 0xFFFF, one below stores its own per mille."""
    from sim_backend.drives.cia402 import Cia402Drive
    from sim_backend.plant import CdprPlant

    model = load_robot(CONFIG / "rowc.toml")
    plant = CdprPlant(model)
    for limit, stored in ((100.0, 0xFFFF), (0.25, 250)):
        drive = Cia402Drive(1, 0, plant, 1.0, 4096, limit, 0.1, (0.0, 0.0), {}, 0.05)
        assert drive.od[(p.OD_MAX_TORQUE, 0)] == stored, limit


def test_an_rpdo_is_taken_only_in_operational():
    """CiA 301: PDOs are exchanged in OPERATIONAL alone; an RPDO that arrives in STOPPED or
    PRE-OPERATIONAL is not latched for the next SYNC."""
    peer = RawPeer()
    try:
        drive = peer.net.nodes[0][1]
        rpdo = 0x200 + 1
        size = drive.pdos.rx.codec.size
        for command, taken in ((0x01, 1), (0x02, 0), (0x80, 0), (0x01, 1)):
            peer.send(0x000, bytes([command, 1]))
            peer.run(0.002)
            before = drive.sync.rpdos
            peer.send(rpdo, bytes(size))
            peer.run(0.002)
            assert drive.sync.rpdos - before == taken, hex(command)
            sent = len(peer.got)
            peer.send(0x080, bytes([1]))  # a SYNC: TPDOs in OPERATIONAL alone
            peer.run(0.002)
            tpdos = [a for _, a, _ in peer.got[sent:] if a == 0x181]
            assert len(tpdos) == taken, hex(command)
    finally:
        peer.close()


def test_after_a_reset_the_first_sync_and_heartbeat_start_afresh():
    """Reset communication, set up again (0x1019 := 240, a heartbeat of 60 s), start: the first
    SYNC's counter (7) is no sign of missed SYNCs — the RPDO before it is taken, not counted
    stale — and the first heartbeat goes out at once, not a period after the reset."""
    peer = RawPeer()
    try:
        drive = peer.net.nodes[0][1]
        size = drive.pdos.rx.codec.size
        peer.send(0x000, bytes([0x01, 1]))
        for counter in (3, 4):  # SYNCs with a counter before the reset
            peer.send(0x080, bytes([counter]))
            peer.run(0.002)
        peer.send(0x000, bytes([0x82, 1]))  # reset communication
        peer.run(0.002)
        t = peer.net.time
        assert peer.sdo(1, bytes([0x2F, 0x19, 0x10, 0, 240, 0, 0, 0]))[0] == 0x60
        assert peer.sdo(1, bytes([0x2B, 0x17, 0x10, 0, *(60000).to_bytes(2, "little"), 0, 0]))[
            0] == 0x60  # fmt: skip
        peer.run(0.003)
        assert [s for _, s in peer.heartbeats(1, since=t)] == [0x7F]  # at once
        peer.send(0x000, bytes([0x01, 1]))
        peer.run(0.002)
        stale, taken = drive.stale_targets, drive.sync.rpdos
        peer.send(0x200 + 1, bytes(size))
        peer.run(0.002)
        assert drive.sync.rpdos == taken + 1
        peer.send(0x080, bytes([7]))
        peer.run(0.002)
        assert drive.stale_targets == stale
    finally:
        peer.close()


def test_a_drive_powered_on_says_boot_up_unless_silent():
    """CiA 301 §7.2.8.2: a node entering PRE-OPERATIONAL after its initialisation sends the
    boot-up message (0x700 + node, one byte 0); a drive made silent (fault injection) sends
    nothing."""
    peer = RawPeer()
    try:
        drive = peer.net.nodes[0][1]
        (frame,) = drive.boot_up()
        assert (frame.arbitration_id, bytes(frame.data)) == (0x701, b"\x00")
        drive.silent = True
        assert drive.boot_up() == []
    finally:
        peer.close()


def test_an_open_safety_chain_faults_a_drive_only_when_its_power_stage_is_on():
    """The STO input open (``Cia402Axis.open_sto``): a disabled drive stays disabled, no
    error, until it is switched on — then FAULT with the STO error and its EMCY at the next
    tick; an enabled one faults at once; no fault reset is taken while the chain is open, the
    error stays after it closes until one is; the brake holds throughout."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as rig:
        drive = rig.net.drives[2]
        axis = drive.axis
        assert axis.state is p.PowerState.SWITCH_ON_DISABLED
        assert drive.open_sto() == [] and axis.state is p.PowerState.SWITCH_ON_DISABLED
        assert axis.fault_code == 0 and rig.plant.brake[2]
        axis.apply_controlword(0x06)  # shutdown: ready to switch on, the stage still off
        assert axis.state is p.PowerState.READY_TO_SWITCH_ON and axis.emcy_due is None
        axis.apply_controlword(0x07)  # switch on: the stage would be energised
        assert axis.state is p.PowerState.FAULT and axis.fault_code == p.EMCY_STO
        emcy = [m for m in drive.tick(rig.net.time) if m.arbitration_id == p.EMCY + 3]
        assert [p.EMCY_STRUCT.unpack(m.data)[0] for m in emcy] == [p.EMCY_STO]
        assert not any(m.arbitration_id == p.EMCY + 3 for m in drive.tick(rig.net.time))
        for cw in (0x00, 0x80):
            axis.apply_controlword(cw)
        assert axis.state is p.PowerState.FAULT and axis.fault_code == p.EMCY_STO
        drive.close_sto()
        assert axis.state is p.PowerState.FAULT and rig.plant.brake[2]  # until acknowledged
        for cw in (0x00, 0x80, 0x06, 0x0F):
            axis.apply_controlword(cw)
        assert axis.state is p.PowerState.OPERATION_ENABLED and axis.fault_code == 0
        frames = drive.open_sto(0xFF20)  # Elmo's code, an enabled drive: at once
        assert axis.state is p.PowerState.FAULT and axis.fault_code == 0xFF20
        assert rig.plant.brake[2] and rig.plant.motor_torque[2] == 0.0
        assert [p.EMCY_STRUCT.unpack(m.data)[0] for m in frames] == [0xFF20]
    assert p.describe_emcy(0x8A88).startswith("safe torque off")


def test_a_brake_that_takes_time_to_close_leaves_the_drum_free_until_it_has():
    """``brake_close_time``: the chain opens on an enabled drive at t; its brake closes
    exactly at t + 30 ms (the physics split there), the drum turning freely before — under
    the cable's tension, paying out — and held after; a reset node meanwhile closes it at
    once."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as rig:
        rig.plant.opt.brake_close_time = 0.03
        drive, net = rig.net.drives[2], rig.net
        axis = drive.axis
        for cw in (0x06, 0x07, 0x0F):
            axis.apply_controlword(cw)
        axis.apply()  # as at the next SYNC: the brake released
        assert axis.state is p.PowerState.OPERATION_ENABLED and not rig.plant.brake[2]
        t0 = net.time
        drive.open_sto(p.EMCY_STO, t0)
        assert axis.state is p.PowerState.FAULT and axis.brake_due == pytest.approx(t0 + 0.03)
        theta0 = rig.plant.theta[2]
        net.advance(0.02)
        assert not rig.plant.brake[2] and rig.plant.motor_torque[2] == 0.0
        assert rig.plant.theta[2] < theta0  # paid out under the tension
        net.advance(0.02)
        assert rig.plant.brake[2] and axis.brake_due == math.inf
        held = rig.plant.theta[2]
        net.advance(0.1)
        assert rig.plant.theta[2] == held
        # enabled again once the chain closes, a new STO, then a reset node: the brake
        # closes at once
        drive.close_sto()
        for cw in (0x80, 0x06, 0x07, 0x0F):
            axis.apply_controlword(cw)
        axis.apply()
        assert axis.state is p.PowerState.OPERATION_ENABLED
        drive.open_sto(p.EMCY_STO, net.time)
        assert not rig.plant.brake[2]
        axis.reset()
        assert rig.plant.brake[2] and axis.brake_due == math.inf


@pytest.mark.parametrize("bad", ["x", "8:4", "-1", "8:12:14", "nan", "8:8"])
def test_a_bad_estop_time_is_one_line_with_the_rule(bad, capsys):
    from cdprctl.cli import main

    assert main(["sim", "--config", str(CONFIG / "rowc.toml"), "--estop", bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    rule = "must be AT or AT:RELEASE in s, 0 <= AT < RELEASE (e.g. 8:12)"
    said = f"{bad!r} is not a time: {rule}" if bad == "x" else f"{bad!r}: {rule}"
    assert err == [f"cdprctl sim: error: --estop = {said}"]


def csp_axis_enabled(rig, cable: int = 2):
    """The drive of ``cable`` switched to position mode and enabled, as at a SYNC without a
    new target: its loop starts where the motor is."""
    axis = rig.net.drives[cable].axis
    axis.od[(p.OD_MODES_OF_OPERATION, 0)] = p.MODE_CSP
    for cw in (0x06, 0x07, 0x0F):
        axis.apply_controlword(cw)
    axis.apply(fresh=False)
    assert axis.state is p.PowerState.OPERATION_ENABLED
    return axis


def test_a_position_loop_enabled_without_a_target_holds_where_the_motor_is():
    """Enabled in position mode with no target yet: the loop's target is the motor's angle,
    not moving (no rate), and the motor stays within a count over 0.2 s."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as rig:
        theta = float(rig.plant.theta[2])
        axis = csp_axis_enabled(rig)
        servo = rig.plant.servo
        assert servo.target[2] == theta and servo.rate[2] == 0.0
        rig.net.advance(0.2)
        assert abs(rig.plant.theta[2] - theta) < 2 * math.pi / axis.cpr


def test_a_huge_following_error_window_is_capped_below_the_value_that_turns_it_off(tmp_path):
    """0x6065 = 0xFFFFFFFF means "no following error monitoring" (CiA 402): a window so large
    it would reach it (here 10^6 m of cable) is written as 0xFFFFFFFE — monitored, never
    silently off."""
    f = tmp_path / "wide.toml"
    f.write_text(f'base = "{CONFIG / "rowc.toml"}"\n[drives]\nfollowing_error_window = 1e6\n')
    with LockStep(load_robot(f), period=0.004) as rig:
        assert list(rig.driver._following_window) == [p.FOLLOWING_ERROR_OFF - 1] * 8
        assert p.FOLLOWING_ERROR_OFF == 0xFFFFFFFF
    # and one smaller than a count is a count: 0 would fault at any error at all
    f.write_text(f'base = "{CONFIG / "rowc.toml"}"\n[drives]\nfollowing_error_window = 1e-9\n')
    with LockStep(load_robot(f), period=0.004) as rig:
        assert list(rig.driver._following_window) == [1] * 8


def test_an_encoder_jump_moves_the_position_loops_target_the_other_way():
    """A jump of +1000 counts (fault injection) in position mode: the drive holds the counts
    it was told, so in the true motor angle its target moves 1000 counts back (0.0959 rad at
    rowc's 65536 counts a turn), and the position actual reads 1000 counts more."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as rig:
        axis = csp_axis_enabled(rig)
        target, before = float(rig.plant.servo.target[2]), axis.counts()
        axis.jump_encoder(1000)
        assert axis.cpr == 65536
        assert rig.plant.servo.target[2] == pytest.approx(target - 0.095873799, abs=1e-9)
        assert axis.counts() == before + 1000


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["sim", "--brake-close-time", "-0.01"], "cdprctl sim: error: --brake-close-time = "
         "-0.01 s must be in [0, 0.5] s (real holding brakes close in 0.01-0.05 s)"),
        (["sim", "--brake-close-time", "0.6"], "cdprctl sim: error: --brake-close-time = 0.6 s "
         "must be in [0, 0.5] s"),
        (["run", "--brake-close-time", "0.03"], "cdprctl run: error: --brake-close-time needs "
         "--sim: it sets the simulated brakes"),
        (["run", "--sim", "--brake-close-time", "1"], "cdprctl run: error: --brake-close-time "
         "= 1 s must be in [0, 0.5] s"),
    ],
)  # fmt: skip
def test_a_bad_brake_close_time_is_one_line_with_the_rule(args, said, capsys):
    from cdprctl.cli import main

    assert main([args[0], "--config", str(CONFIG / "rowc.toml"), *args[1:]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(said), err


def test_an_estop_time_is_the_event_it_says():
    from cdprctl.commands.sim import estop_event

    ev = estop_event("8:12", "cia402")
    assert (ev.time, ev.kind, ev.duration, ev.value) == (8.0, "estop", 4.0, 0)
    assert math.isinf(estop_event("3", "cia402").duration)
    assert "no safety chain" in estop_event("3", "odrive")


def test_an_enabled_drive_gives_no_torque_before_its_first_rpdo_and_reports_what_it_gives():
    """Enabled in torque mode with no RPDO taken yet: no torque, and 0x6077 says 0. With no
    mode set (0x6060 = 0, its power-on value) a torque it gives is what 0x6077 reports at
    once — only position mode reports its loop's torque (of the last physics step)."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as rig:
        axis = rig.net.drives[2].axis
        axis.od[(p.OD_MODES_OF_OPERATION, 0)] = p.MODE_CST
        for cw in (0x06, 0x07, 0x0F):
            axis.apply_controlword(cw)
        axis.apply(fresh=False)
        assert axis.state is p.PowerState.OPERATION_ENABLED
        assert rig.plant.motor_torque[2] == 0.0 and axis.torque_actual_pm() == 0
        axis.od[(p.OD_MODES_OF_OPERATION, 0)] = 0
        axis.take(rig.net.time, 200, None, None)
        axis.apply(fresh=False)
        assert rig.plant.motor_torque[2] == pytest.approx(0.2 * axis.rated_torque)
        assert axis.torque_actual_pm() == 200


def test_an_absolute_encoder_reads_the_motor_angle_to_half_a_count():
    """An absolute encoder (the shipped drives') counts from the motor angle's zero, not from
    where the drive powered on: the master reads each motor within half a count of the
    plant's angle (a count off is a bias no test of motion would see)."""
    model = load_robot(CONFIG / "rowc.toml")
    with LockStep(model, period=0.004) as ls:
        ls.driver.configure()
        read = ls.driver.read(ls.net.time).position
        assert not any(d.axis.incremental for d in ls.net.drives)
        half = np.array([math.pi / c.winch.encoder_counts_per_rev for c in model.cables])
        assert np.all(np.abs(read - ls.net.plant.theta) <= half)
        assert np.any(np.abs(ls.net.plant.theta) > 100 * half)  # not all at the zero itself


def test_a_drive_takes_only_the_modes_its_0x6502_has():
    """0x6502's bits (CiA 402 §6.4.7): bit 7 cyclic synchronous position, bit 9 torque — a
    drive with one of them refuses the other."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        axis = ls.net.drives[0].axis
        for bits, csp, cst in ((1 << 7, True, False), (1 << 9, False, True), (0x280, True, True)):
            axis.od[(p.OD_SUPPORTED_DRIVE_MODES, 0)] = bits
            assert (axis.supports_mode(p.MODE_CSP), axis.supports_mode(p.MODE_CST)) == (csp, cst)


def test_a_position_target_is_reached_over_a_period_but_after_a_gap_at_once():
    """Mode 8: a new target within ``extrapolate_for`` of the last SYNC (at once included: a
    burst) is reached one SYNC period on (a rate); one after a gap of ``extrapolate_for`` or
    more, or before the drive has a period, is a step — a rate over a stale or unknown period
    would be made up."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        ls.driver.configure()  # mode 8 set by SDO
        axis, servo, theta = ls.net.drives[0].axis, ls.net.plant.servo, ls.net.plant.theta
        axis.state = p.PowerState.OPERATION_ENABLED
        assert axis.mode == p.MODE_CSP
        axis.apply(fresh=False)  # just enabled: the loop holds where the motor is
        start = float(servo.target[0])
        assert start == theta[0]
        axis.target_counts = axis.counts() + 100
        end = theta[0] + 100 * 2.0 * math.pi / axis.cpr
        gap = axis.extrapolate_for
        ramp = (end - start) / 0.004
        for interval, period, rate in ((0.004, 0.004, ramp), (0.0, 0.004, ramp),
                                       (gap, 0.004, None), (2 * gap, 0.004, None),
                                       (0.004, 0.0, None)):  # fmt: skip
            servo.target[0], servo.rate[0] = start, 0.0
            axis.apply(interval, fresh=True, period=period)
            if rate is None:  # a step
                assert (servo.target[0], servo.rate[0]) == (pytest.approx(end, abs=1e-12), 0.0)
            else:
                assert servo.target[0] == start
                assert servo.rate[0] == pytest.approx(rate, rel=1e-12)


def test_the_following_error_objects_become_the_loops_window_and_time_out():
    """0x6065 (counts) and 0x6066 (ms, CiA 402 §6.8.4-5) as the drive's position loop takes
    them: rad at the motor and s."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        axis, servo = ls.net.drives[2].axis, ls.net.plant.servo
        axis.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] = 1000
        axis.od[(p.OD_FOLLOWING_ERROR_TIMEOUT, 0)] = 250
        axis.set_following_error()
        assert servo.window[2] == pytest.approx(1000 / axis.cpr * 2 * math.pi, rel=1e-15)
        assert servo.timeout[2] == 0.25


def test_a_position_loop_of_low_gain_goes_on_from_its_target():
    """Only a loop that was off (kp = 0) starts where the motor is: one whose gain is below
    1 N·m/rad (a small motor) goes on from its target at every SYNC, as any other."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        ls.driver.configure()  # mode 8 set by SDO
        axis, servo, theta = ls.net.drives[0].axis, ls.net.plant.servo, ls.net.plant.theta
        axis.position_gains = (0.5, 0.01)  # N·m/rad, N·m·s/rad
        axis.state = p.PowerState.OPERATION_ENABLED
        axis.apply(fresh=False)  # just enabled: the loop holds where the motor is
        assert (servo.target[0], servo.kp[0]) == (theta[0], 0.5)
        servo.target[0] = theta[0] + 0.1  # where its interpolation has got to
        axis.apply(fresh=False)
        assert servo.target[0] == theta[0] + 0.1


def test_the_drive_reports_velocity_in_counts_per_second_and_its_limit_from_0x6072():
    """0x606C as a master reads it: the motor's speed in counts/s (10 rad/s on 65,536 counts a
    turn: 104,304); 0x6072 per mille of the rated torque as the limit the power stage keeps,
    where it is below the winch's own."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        drive, axis = ls.net.drives[1], ls.net.drives[1].axis
        assert axis.cpr == 65536
        ls.net.plant.theta_dot[1] = 10.0  # rad/s
        reply = drive.on_sdo(p.sdo_upload(p.OD_VELOCITY_ACTUAL, 0))
        assert int.from_bytes(reply.data[4:8], "little", signed=True) == 104304
        axis.od[(p.OD_MAX_TORQUE, 0)] = 100  # ‰
        assert axis.effective_torque_limit == pytest.approx(0.1 * axis.rated_torque, rel=1e-12)
        assert axis.effective_torque_limit < axis.torque_limit


def test_a_moving_target_is_held_extrapolate_for_after_the_last_one_at_any_rate():
    """Mode 8 without new targets: the target goes on at its last rate until
    ``extrapolate_for`` after the last one came, then holds — at 1 rad/s as at any rate."""
    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        axis, servo = ls.net.drives[0].axis, ls.net.plant.servo
        servo.rate[0], axis.last_target = 1.0, 2.0  # rad/s, s
        due = 2.0 + axis.extrapolate_for
        assert axis.holds_at() == due
        axis.hold_if_due(due - 1e-6)
        assert servo.rate[0] == 1.0
        axis.hold_if_due(due)
        assert servo.rate[0] == 0.0


def test_switching_on_with_the_safety_chain_open_faults_with_the_sto_error():
    """A drive disabled when the chain opened stays so; the master's shutdown (to ready, the
    power stage still off) is taken, its switch-on (energising it) faults the drive with the
    STO error and an EMCY due."""
    with enabled_rig("rowc.toml") as rig:
        axis = rig.net.drives[2].axis
        axis.state = p.PowerState.SWITCH_ON_DISABLED
        assert axis.open_sto(p.EMCY_STO) is False
        axis.apply_controlword(0x06)  # shutdown
        assert axis.state is p.PowerState.READY_TO_SWITCH_ON and axis.emcy_due is None
        axis.apply_controlword(0x07)  # switch on
        assert axis.state is p.PowerState.FAULT
        assert axis.fault_code == axis.emcy_due == p.EMCY_STO


def test_a_reset_node_clears_the_error_code():
    """A faulted drive's reset node (NMT): the state machine restarts and 0x603F reads 0."""
    with enabled_rig("rowc.toml") as rig:
        axis = rig.net.drives[1].axis
        axis.fault(p.EMCY_FOLLOWING_ERROR)
        assert axis.fault_code == p.EMCY_FOLLOWING_ERROR
        axis.reset()
        assert axis.state is p.PowerState.SWITCH_ON_DISABLED and axis.fault_code == 0


def test_a_negative_target_torque_is_applied_and_clamped_at_minus_the_limit():
    """Torque mode: a target torque paying cable out (negative) is applied as it is within
    the limit, at −limit beyond it; and 0x6077 reports the torque applied since the SYNC that
    set it, before any physics step (the servo's last applied torque is the one before)."""
    with enabled_rig("seed000.toml", torque_mode=True) as rig:
        axis, c = rig.net.drives[0].axis, rig.net.drives[0].axis.cable
        limit, rated = axis.effective_torque_limit, axis.rated_torque
        axis.torque_pm = -round(0.5 * limit / rated * 1000)
        axis.apply()
        assert rig.plant.motor_torque[c] == pytest.approx(-0.5 * limit, rel=1e-3)
        assert rig.plant.servo.applied[c] != rig.plant.motor_torque[c]  # no step since
        assert axis.torque_actual_pm() == axis.torque_pm
        axis.torque_pm = -32000
        axis.apply()
        assert rig.plant.motor_torque[c] == -limit


def test_a_closing_brake_is_closed_at_any_instant_from_its_due_time_on():
    """A brake released by an opening chain closes at ``brake_due``: checked at an instant
    just past it (a tick need not land on it exactly), it is closed; just before, still open."""
    with enabled_rig("rowc.toml") as rig:
        axis, c = rig.net.drives[4].axis, rig.net.drives[4].axis.cable
        rig.plant.brake[c] = False
        axis.brake_due = 1.0  # s
        axis.hold_if_due(1.0 - 1e-9)
        assert not rig.plant.brake[c]
        axis.hold_if_due(1.0 + 1e-9)
        assert rig.plant.brake[c] and axis.brake_due == math.inf


def test_no_position_loop_runs_outside_mode_8():
    """Enabled with 0x6060 at its default 0 (no mode: the master set none), the drive runs no
    position loop; set to 8 (cyclic synchronous position), it does."""
    with enabled_rig("seed000.toml", torque_mode=True) as rig:
        axis, c = rig.net.drives[3].axis, rig.net.drives[3].axis.cable
        assert axis.state is p.PowerState.OPERATION_ENABLED
        axis.od[(p.OD_MODES_OF_OPERATION, 0)] = 0
        axis.apply()
        assert rig.plant.servo.kp[c] == 0.0
        axis.od[(p.OD_MODES_OF_OPERATION, 0)] = p.MODE_CSP
        axis.apply()
        assert rig.plant.servo.kp[c] > 0.0


def test_a_held_fault_reset_bit_resets_once():
    """A fault reset is bit 7's rising edge (CiA 402 §6.3.1.1): held high, it reset the drive
    once; a fault meanwhile stays until the bit falls and rises again."""
    with enabled_rig("rowc.toml") as rig:
        axis = rig.net.drives[0].axis
        axis.fault(p.EMCY_FOLLOWING_ERROR)
        axis.apply_controlword(0x80)
        assert axis.state is p.PowerState.SWITCH_ON_DISABLED
        axis.fault(p.EMCY_FOLLOWING_ERROR)
        axis.apply_controlword(0x80)  # still high
        assert axis.state is p.PowerState.FAULT
        axis.apply_controlword(0x00)
        axis.apply_controlword(0x80)
        assert axis.state is p.PowerState.SWITCH_ON_DISABLED


def test_an_opening_chain_lets_only_a_released_brake_take_its_closing_time():
    """The chain opens at t = 1 s with brakes that take 30 ms to close: a drive enabled with
    its brake released lets the drum turn until 1.03 s; one enabled against its closed brake
    (a brake test) keeps it closed."""
    with enabled_rig("rowc.toml") as rig:
        rig.plant.opt.brake_close_time = 0.03  # s
        free, held = rig.net.drives[0].axis, rig.net.drives[1].axis
        rig.plant.close_brake(held.cable)
        assert not rig.plant.brake[free.cable] and rig.plant.brake[held.cable]
        assert free.open_sto(p.EMCY_STO, t=1.0) and held.open_sto(p.EMCY_STO, t=1.0)
        assert free.brake_due == pytest.approx(1.03) and not rig.plant.brake[free.cable]
        assert held.brake_due == math.inf and rig.plant.brake[held.cable]


def test_a_target_moving_at_any_rate_is_held_after_the_extrapolation_time():
    """A position target moving (at −1 rad/s, say) holds ``extrapolate_for`` after the last
    new one (``holds_at`` says when, ``hold_if_due`` holds it); a still one never needs
    holding."""
    with enabled_rig("rowc.toml") as rig:
        axis, rate = rig.net.drives[6].axis, rig.plant.servo.rate
        axis.last_target = 2.0  # s
        rate[axis.cable] = -1.0  # rad/s
        due = axis.holds_at()
        assert due == 2.0 + axis.extrapolate_for
        axis.hold_if_due(due - 1e-9)
        assert rate[axis.cable] == -1.0
        axis.hold_if_due(due)
        assert rate[axis.cable] == 0.0
        assert axis.holds_at() == math.inf


def test_a_position_rpdo_without_a_torque_offset_applies_none():
    """Mode 8 with an RPDO that maps no torque offset (0x60B2): the offset is 0, not a
    leftover; and a drive disabled starts its following-error time from 0 again."""
    with enabled_rig("rowc.toml") as rig:
        axis, servo = rig.net.drives[5].axis, rig.plant.servo
        axis.od[(p.OD_MODES_OF_OPERATION, 0)] = p.MODE_CSP
        axis.torque_pm = 250
        assert axis.take(1.0, None, 1000, None) is True
        assert axis.torque_pm == 0
        servo.beyond[axis.cable] = 0.05  # s beyond the window so far
        axis.state = p.PowerState.SWITCH_ON_DISABLED
        axis.apply()
        assert servo.beyond[axis.cable] == 0.0


def test_a_reset_node_keeps_an_absolute_encoders_count():
    """A reset node restarts an incremental encoder's counter at zero, never an absolute
    one's: with the motor a radian off its start, the count reads the same after."""
    with enabled_rig("rowc.toml") as rig:
        axis = rig.net.drives[2].axis
        assert not axis.incremental
        rig.plant.theta[axis.cable] += 1.0  # rad
        before = axis.counts()
        assert before != 0
        axis.reset()
        assert axis.counts() == before


def test_the_torque_actual_saturates_at_its_16_bit_range():
    """0x6077 is an INTEGER16 per mille of the rated torque: with a rated torque written as
    1 mN·m (0x6076), a torque of ±1 N·m reads ±32767, never wrapped or short of it."""
    with enabled_rig("seed000.toml", torque_mode=True) as rig:
        axis, c = rig.net.drives[2].axis, rig.net.drives[2].axis.cable
        axis.rated_torque = 0.001  # N·m
        for sign in (1.0, -1.0):
            rig.plant.motor_torque[c] = sign * 1.0
            assert axis.torque_actual_pm() == sign * 32767
