"""The ``[[drives.buses]]`` tables of a robot description: which cables' drives are on which
CAN bus, with which node ids, python-can options and DCF files (``docs/config.md``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdprctl.model.reader import TableReader

BUS_KEYS = ("interface", "channel", "bitrate", "cables", "node_ids", "options", "dcf")


@dataclass(frozen=True)
class BusConfig:
    interface: str  # python-can interface: socketcan, virtual, udp_multicast, pcan, ...
    channel: str
    bitrate: int  # bit/s
    cables: tuple[int, ...]  # 0-based cable indices on this bus
    node_ids: tuple[int, ...]  # drive node id of each of those cables
    options: dict[str, Any] = field(default_factory=dict)  # any other python-can argument
    # per drive: a DCF/EDS whose ParameterValues the driver writes at set-up ("": none)
    dcf: tuple[str, ...] = ()

    def dcf_of(self, k: int) -> str:
        """The DCF of the bus's ``k``-th drive ("": none)."""
        return self.dcf[k] if k < len(self.dcf) else ""


# the node ids each protocol can address: CANopen's 7-bit ids (0 is NMT's "all nodes"); CAN
# Simple's 6-bit axis ids, 0x3F reserved for an ODrive not yet given one
NODE_IDS = {
    "cia402": (1, 127, "a CANopen node id"),
    "odrive": (0, 62, "an ODrive axis's CAN Simple node id (axis0.config.can.node_id)"),
}


def default_buses(name: str, n_cables: int) -> tuple[BusConfig, ...]:
    """One simulated bus: node ids 1..m on python-can's ``virtual`` interface."""
    return (
        BusConfig(
            interface="virtual",
            channel=f"cdpr-{name}",
            bitrate=1_000_000,
            cables=tuple(range(n_cables)),
            node_ids=tuple(range(1, n_cables + 1)),
        ),
    )


def read_buses(
    rd: TableReader, t: dict[str, Any], cable_names: list[str], name: str, ctrl_id: float | None,
    driver: str = "cia402",
) -> list[BusConfig]:
    """The ``[[drives.buses]]`` of the ``[drives]`` table ``t``: each cable on exactly one bus,
    node ids in the ``driver``'s range (``NODE_IDS``), unique on a bus and not the controller's
    (``ctrl_id``); without any, the default simulated bus."""
    buses: list[BusConfig] = []
    seen_cable: dict[int, str] = {}
    raw = t.get("buses")
    if raw is None:  # the default simulated bus
        raw = []
        buses.extend(default_buses(name, len(cable_names)))
        seen_cable.update({i: "the default bus" for i in range(len(cable_names))})
    elif not isinstance(raw, list) or not raw or not all(isinstance(b, dict) for b in raw):
        rd.errors.append(
            f"{rd.file}: drives.buses must be an array of tables [[drives.buses]], at least one"
        )
        raw = []
    for bi, bt in enumerate(raw):
        path = f"drives.buses[{bi}]"
        rd.check_keys(bt, BUS_KEYS, path)
        iface = rd.string(bt, "interface", path)
        channel = bt.get("channel")
        if not isinstance(channel, str | int) or isinstance(channel, bool):
            rd.error(f"{path}.channel", channel, "", "must be a string (or an integer)")
            channel = None
        bitrate = rd.number(
            bt,
            "bitrate",
            path,
            "bit/s",
            required=False,
            default=1_000_000,
            positive=True,
            integer=True,
        )
        cables = bt.get("cables")
        idx = _bus_cables(rd, path, cables, cable_names, seen_cable)
        nodes = _bus_nodes(rd, path, bt.get("node_ids"), cables, driver, ctrl_id)
        options = bt.get("options", {})
        if not isinstance(options, dict):
            rd.error(f"{path}.options", options, "", "must be a table of python-can arguments")
            options = {}
        dcf = _read_dcf(rd, bt.get("dcf"), f"{path}.dcf", len(nodes) if nodes else 0)
        if iface and channel is not None and bitrate is not None:
            buses.append(
                BusConfig(
                    iface,
                    str(channel),
                    int(bitrate),
                    tuple(idx),
                    tuple(int(n) for n in nodes),
                    dict(options),
                    dcf,
                )
            )
    missing = [cable_names[i] for i in range(len(cable_names)) if i not in seen_cable]
    if raw and missing:
        rd.errors.append(
            f"{rd.file}: drives.buses: cables {', '.join(missing)} are on no bus: every cable "
            "needs a drive"
        )
    return buses


def _bus_cables(rd: TableReader, path: str, cables: Any, cable_names: list[str],
                seen_cable: dict[int, str]) -> list[int]:  # fmt: skip
    """The indices of a bus's ``cables`` (names), each on no other bus (``seen_cable``: where
    each cable is so far, updated)."""
    idx: list[int] = []
    if not isinstance(cables, list) or not all(isinstance(c, str) for c in cables):
        rd.error(f"{path}.cables", cables, "", "must be a list of cable names")
        return idx
    for c in cables:
        if c not in cable_names:
            rd.error(f"{path}.cables", c, "", f"is not a cable ({', '.join(cable_names)})")
        elif cable_names.index(c) in seen_cable:
            rd.error(
                f"{path}.cables",
                c,
                "",
                f"is already on {seen_cable[cable_names.index(c)]}: one bus per cable",
            )
        else:
            seen_cable[cable_names.index(c)] = path
            idx.append(cable_names.index(c))
    return idx


def _bus_nodes(rd: TableReader, path: str, nodes: Any, cables: Any, driver: str,
               ctrl_id: float | None) -> list[int]:  # fmt: skip
    """A bus's ``node_ids``, one per cable, in the ``driver``'s range, unique, not the
    controller's (``ctrl_id``); [] where they are no list of integers."""
    if (
        not isinstance(nodes, list)
        or not all(isinstance(n, int) and not isinstance(n, bool) for n in nodes)
        or (isinstance(cables, list) and len(nodes) != len(cables))
    ):
        rd.error(
            f"{path}.node_ids",
            nodes,
            "",
            "must be a list of integers, one per cable of the bus",
        )
        return []
    lo, hi, what = NODE_IDS.get(driver, NODE_IDS["cia402"])
    for n in nodes:
        if not lo <= n <= hi:
            rd.error(f"{path}.node_ids", n, "", f"must be {what} in [{lo}, {hi}]")
    dups = sorted({n for n in nodes if nodes.count(n) > 1})
    if dups:
        rd.error(
            f"{path}.node_ids",
            nodes,
            "",
            f"repeats node id {dups[0]}: node ids on a bus must be unique",
        )
    if ctrl_id is not None and int(ctrl_id) in nodes:
        rd.error(
            f"{path}.node_ids",
            nodes,
            "",
            f"contains the controller's node id {int(ctrl_id)}",
        )
    return nodes


def _read_dcf(rd: TableReader, value: Any, path: str, n: int) -> tuple[str, ...]:
    """``dcf``: one file for every drive of the bus, or a list of one per drive ("" for
    none); relative paths from the config file's folder; each must exist (parsed at set-up)."""
    if value is None:
        return ()
    files = [value] * n if isinstance(value, str) else value
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        rd.error(path, value, "", "must be a file name, or a list of one per drive")
        return ()
    if len(files) != n:
        rd.error(path, value, "", f"must list one file per drive of the bus ({n}), '' for none")
        return ()
    base = Path(rd.file).parent
    out = []
    for f in files:
        full = "" if not f else str((base / f) if not Path(f).is_absolute() else Path(f))
        if full and not Path(full).is_file():
            rd.error(path, f, "", f"no such file ({full}; relative to the config file's folder)")
        out.append(full)
    return tuple(out)
