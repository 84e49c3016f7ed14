"""What is on a CAN bus, for commissioning (``cdprctl drives scan``): every node that answers an
SDO upload of 0x1000 or sends a heartbeat, and per node what cdprctl's set-up would meet —
identity, device type, supported modes, rated torque, which optional objects it has, its
PDO mappings — with a verdict per mode. Read-only: SDO uploads only, no NMT command, no SYNC,
nothing written. The `canopen` package is the master here (its node scanner, its SDO client
with segmented uploads for the device name); the judgement is the set-up's own
(``capabilities``, ``drive_setup.OPTIONAL``), so the scan and a start cannot disagree."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any

import can
import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from drivers.cia402 import pdo_setup
from drivers.cia402 import protocol as p
from drivers.cia402.capabilities import Capabilities, rated_torque_problem, read_capabilities
from drivers.cia402.drive_setup import OPTIONAL, POSITION_ONLY
from drivers.errors import SdoAbortError

OD_DEVICE_NAME = 0x1008  # VISIBLE_STRING, often longer than 4 bytes (a segmented upload)
NMT_STATE_NAMES = {0x00: "boot-up", 0x04: "stopped", 0x05: "operational", 0x7F: "pre-operational"}
PDOS = [(f"RPDO{k}", 0x1400 + k - 1, 0x1600 + k - 1) for k in range(1, 5)] + [
    (f"TPDO{k}", 0x1800 + k - 1, 0x1A00 + k - 1) for k in range(1, 5)
]


@dataclass
class NodeReport:
    node: int
    nmt: str  # from its heartbeat, or why there was none
    device_name: str | None
    capabilities: Capabilities | None  # None: the node answered no SDO
    pdos: dict[str, str] = field(default_factory=dict)  # name → COB-ID, type and mapping
    cable: int | None = None  # the cable index this node drives in the config (None: none)
    configured_mode: str | None = None  # "csp" / "cst" as the config has it
    verdicts: dict[str, str] = field(default_factory=dict)  # "csp"/"cst" → "yes" / "no: why"
    would_skip: list[str] = field(default_factory=list)
    # PDO name → (COB-ID, transmission type, entries) as found (pdo_setup.found)
    found: dict[str, tuple[int, int, tuple[int, ...] | None]] = field(default_factory=dict)

    @property
    def can_run_configured(self) -> bool:
        return self.configured_mode is not None and self.verdicts.get(
            self.configured_mode, "").startswith("yes")  # fmt: skip

    def as_json(self) -> dict[str, Any]:
        out = asdict(self)
        del out["found"]
        caps = self.capabilities
        out["capabilities"] = None if caps is None else {
            "identity": caps.identity, "device_type": caps.device_type,
            "supported_drive_modes": caps.modes, "rated_torque_mNm": caps.rated_torque,
            "optional_objects": {f"0x{k:04X}": v for k, v in caps.present.items()},
        }  # fmt: skip
        return out


def _reader(node: canopen.RemoteNode, node_id: int):
    def read(index: int, sub: int) -> int:
        try:
            data = node.sdo.upload(index, sub)
        except SdoAbortedError as exc:
            raise SdoAbortError(str(exc), node_id, index, sub, exc.code) from None
        return int.from_bytes(data[:4], "little")

    return read


def _pdo_text(found: tuple[int, int, tuple[int, ...] | None]) -> str:
    cob, transmission, entries = found
    state = "disabled" if cob & p.PDO_NOT_VALID else "enabled"
    return (f"COB-ID 0x{cob:08X} ({state}), transmission type {transmission}, "
            f"{pdo_setup.describe(entries)}")  # fmt: skip


def scan_bus(bus: can.BusABC, listen: float, sdo_timeout: float) -> list[NodeReport]:
    """Every node on ``bus``: found by an SDO upload of 0x1000 to nodes 1-127 and by the
    heartbeats heard over ``listen`` s; then each read (``sdo_timeout`` s an answer)."""
    network = canopen.Network(bus)
    heard: dict[int, int] = {}

    def on_heartbeat(can_id: int, data: bytearray, timestamp: float) -> None:
        if data:
            heard[can_id - p.HEARTBEAT] = data[0]

    for n in range(1, 128):
        network.subscribe(p.HEARTBEAT + n, on_heartbeat)
    network.connect()
    try:
        network.scanner.search()
        time.sleep(listen)
        found = sorted(set(network.scanner.nodes) | set(heard))
        reports = []
        for n in found:
            node = canopen.RemoteNode(n, canopen.ObjectDictionary())
            node.sdo.RESPONSE_TIMEOUT = sdo_timeout
            network.add_node(node)
            reports.append(_read_node(node, n, heard.get(n)))
        return reports
    finally:
        if network.notifier is not None:
            network.notifier.stop()  # the bus is the caller's to shut down


def _read_node(node: canopen.RemoteNode, node_id: int, heartbeat: int | None) -> NodeReport:
    read = _reader(node, node_id)
    nmt = ("no heartbeat heard (0x1017 = 0?)" if heartbeat is None
           else NMT_STATE_NAMES.get(heartbeat, f"state 0x{heartbeat:02X}"))  # fmt: skip
    try:
        name: str | None = node.sdo.upload(OD_DEVICE_NAME, 0).decode("latin-1").strip("\0 ")
    except (SdoAbortedError, SdoCommunicationError):
        name = None
    try:
        caps = read_capabilities(read, tuple(OPTIONAL))
    except SdoCommunicationError:
        return NodeReport(node_id, nmt, name, None)
    report = NodeReport(node_id, nmt, name, caps)
    for pdo_name, comm, mapping in PDOS:
        try:
            found = pdo_setup.found(read, pdo_setup.Pdo("", comm, mapping, 0, ()))
        except (SdoAbortError, SdoCommunicationError):
            continue  # a PDO the drive does not have
        report.found[pdo_name] = found
        report.pdos[pdo_name] = _pdo_text(found)
    return report


def judge(report: NodeReport, cable: int | None, cfg: Any, dcf: str = "") -> None:
    """The verdicts of ``report`` for cdprctl, by the set-up's own rules: per cyclic
    synchronous mode, can it run (``Capabilities.can_run``; the rated torque against
    ``[drives] rated_torque``; with ``pdo_mapping = "static"`` the mappings as found), and
    what the set-up would skip of what is absent. ``cable``: the cable index the config gives
    this node (None: not configured); ``cfg``: ``[drives]``; ``dcf``: the node's DCF, whose
    values the set-up writes first (they may change what was read)."""
    report.cable = cable
    report.configured_mode = None if cable is None else cfg.mode_of(cable)
    caps = report.capabilities
    if caps is None:
        report.verdicts = {name: "no: it answers no SDO" for name in p.MODE_SHORT_NAMES.values()}
        return
    rated_mnm = cfg.rated_torque * 1000.0
    for m, name in p.MODE_SHORT_NAMES.items():
        why = caps.can_run(m) or rated_torque_problem(caps.rated_torque, rated_mnm)
        if why is None and cfg.pdo_mapping == "static":
            why = _static_mapping_problem(report, m, cfg.velocity_source == "pdo")
        if why is not None:
            report.verdicts[name] = f"no: {why}"
        elif caps.modes is None:
            report.verdicts[name] = "yes, unless the mode is refused (0x6502 holds no value)"
        else:
            report.verdicts[name] = "yes"
        if dcf and why is not None:
            report.verdicts[name] += f" (before {dcf}'s values, which the set-up writes first)"
    for index, present in caps.present.items():
        if not present and (index not in POSITION_ONLY or report.configured_mode == "csp"):
            obj, lost = OPTIONAL[index]
            report.would_skip.append(f"0x{index:04X} {obj} (absent): {lost}")
    if caps.rated_torque is None:
        report.would_skip.append(
            f"0x6076 motor rated torque (absent): torques in per mille of {rated_mnm:.0f} mN·m "
            "as [drives] rated_torque says")  # fmt: skip


def judge_bus(reports: list[NodeReport]) -> None:
    """What one drive does to its medium's others: a drive without 0x1019 takes the SYNC
    counter off the bus (drive_setup: 0x1019 := 0 where a drive has it)."""
    without = [r.node for r in reports if r.capabilities is not None
               and not r.capabilities.present.get(p.OD_SYNC_COUNTER_OVERFLOW, True)]  # fmt: skip
    if not without:
        return
    for r in reports:
        if r.capabilities is not None and r.node not in without:
            r.would_skip.append(
                f"the SYNC counter (0x1019 := 0): node {', '.join(map(str, without))} on its "
                "bus has no 0x1019, so the SYNC there goes without one")  # fmt: skip


def _static_mapping_problem(report: NodeReport, mode: int, velocity: bool) -> str | None:
    """With ``pdo_mapping = "static"``: what differs from the PDOs cdprctl's codec needs."""
    for pdo in pdo_setup.wanted(mode, report.node, velocity):
        found = report.found.get(pdo.name)
        diff = ["not readable"] if found is None else pdo_setup.differences(pdo, *found)
        if diff:
            return (f"{pdo.name} is not what cdprctl's codec needs and [drives] pdo_mapping = "
                    f"\"static\": {'; '.join(diff)}")  # fmt: skip
    return None
