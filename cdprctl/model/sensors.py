"""The ``[sensors]`` section: load cells measuring cables' tensions over CANopen — a CiA 404
measuring device, or a drive's analog input mapped into a TPDO (docs/config.md, "Load cells").

A cell is read as ``tension = scale · value + offset`` (N), ``value`` the object its TPDO
carries. The objects a CiA 404 device offers for its analog input's process value (CiA 404
§6, "AI input PV"): 0x6130 as REAL32, 0x7130 as INTEGER16, 0x9130 as INTEGER32; any other
object (a drive's analog input, a vendor's object) names its ``data_type``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cdprctl.model.buses import BusConfig
from cdprctl.model.reader import TableReader

SENSORS_KEYS = ("load_cells", "estimate_error", "disagreement_time")
LOAD_CELL_KEYS = ("cable", "node_id", "bus", "object", "subindex", "data_type", "tpdo", "scale",
                  "offset", "accuracy", "timeout")  # fmt: skip
#: CiA 404's analog input process values and their types (the default ``data_type``)
CIA404_PV_TYPES = {0x6130: "real32", 0x7130: "int16", 0x9130: "int32"}
DATA_TYPES = ("int16", "int32", "real32")
#: bytes each type takes in a PDO
DATA_SIZES = {"int16": 2, "int32": 4, "real32": 4}


@dataclass(frozen=True)
class LoadCell:
    """One cable's load cell: where its value comes from and how it becomes newtons."""

    cable: int  # the cable's index
    bus: int  # index of its bus in [[drives.buses]]
    node_id: int  # its CANopen node id
    object: int  # the object its TPDO carries (index)
    subindex: int
    data_type: str  # "int16", "int32" or "real32"
    tpdo: int  # 1-4: which of the node's TPDOs (COB-ID 0x180 + 0x100 (tpdo − 1) + node)
    scale: float  # N per unit of the value
    offset: float  # N: the tension at a value of 0 (`cdprctl load-cells zero` measures it)
    accuracy: float  # N: the most the cell's reading may be off the tension (datasheet)
    timeout: float  # s without a value: the cell is dead

    @property
    def cob_id(self) -> int:
        """The COB-ID of the TPDO that carries the value."""
        return 0x180 + 0x100 * (self.tpdo - 1) + self.node_id


@dataclass(frozen=True)
class SensorsConfig:
    load_cells: tuple[LoadCell, ...] = ()
    # N: the most the tension taken from a drive's torque may be off (friction, pulley
    # losses, the rotor's inertia): the cell and the estimate disagree beyond
    # accuracy + estimate_error
    estimate_error: float = 10.0
    # s the disagreement (or a cell's silence) must persist before it is a fault: a cell's
    # noise and a transient ride through; within it the fault is named (< 100 ms)
    disagreement_time: float = 0.05

    def cell_of(self, cable: int) -> LoadCell | None:
        """The load cell on cable index ``cable`` (None: its tension comes from its torque)."""
        for cell in self.load_cells:
            if cell.cable == cable:
                return cell
        return None


def read_sensors(rd: TableReader, data: dict[str, Any], cable_names: list[str],
                 buses: tuple[BusConfig, ...], controller_id: int,
                 driver: str = "cia402") -> SensorsConfig:  # fmt: skip
    """``[sensors]`` (optional) with its ``[[sensors.load_cells]]``; errors go to ``rd``.
    ``buses``: the drives' (a cell is on one of them, its node id none of theirs)."""
    n0 = len(rd.errors)
    t = rd.section(data, "sensors", SENSORS_KEYS)
    if t is None:
        return SensorsConfig()
    d = SensorsConfig()
    err = rd.number(t, "estimate_error", "sensors", "N", required=False,
                    default=d.estimate_error, positive=True)  # fmt: skip
    hold = rd.number(t, "disagreement_time", "sensors", "s", required=False,
                     default=d.disagreement_time, positive=True, maximum=0.1)  # fmt: skip
    raw = t.get("load_cells", [])
    if not isinstance(raw, list) or not all(isinstance(c, dict) for c in raw):
        rd.errors.append(f"{rd.file}: sensors.load_cells must be an array of tables "
                         "[[sensors.load_cells]]")  # fmt: skip
        raw = []
    if raw and driver != "cia402":
        rd.error("sensors.load_cells", f"{len(raw)} cells", "", f"need CANopen buses: the "
                 f"drives' (drives.driver = {driver!r}) speak CAN Simple, whose frame ids are "
                 "CANopen's too")  # fmt: skip
        raw = []
    cells: list[LoadCell] = []
    used: dict[tuple[int, int], str] = {}
    for b, bus in enumerate(buses):
        used.update({(b, n): f"the drive of {cable_names[c]}"
                     for c, n in zip(bus.cables, bus.node_ids, strict=True)})  # fmt: skip
        used[(b, controller_id)] = "the controller (drives.controller_node_id)"
    for i, ct in enumerate(raw):
        cell = _read_cell(rd, ct, f"sensors.load_cells[{i}]", cable_names, buses, used, cells)
        if cell is not None:
            cells.append(cell)
    if len(rd.errors) > n0 or err is None or hold is None:
        return d
    return SensorsConfig(tuple(cells), err, hold)


def _read_cell(rd: TableReader, ct: dict[str, Any], path: str, names: list[str],
               buses: tuple[BusConfig, ...], used: dict[tuple[int, int], str],
               cells: list[LoadCell]) -> LoadCell | None:  # fmt: skip
    """One ``[[sensors.load_cells]]`` table (None: refused, said in ``rd``)."""
    rd.check_keys(ct, LOAD_CELL_KEYS, path)
    name = rd.string(ct, "cable", path)
    cable = None
    if name is not None and name not in names:
        rd.error(f"{path}.cable", name, "", f"is not a cable ({', '.join(names)})")
    elif name is not None:
        cable = names.index(name)
        if any(c.cable == cable for c in cells):
            rd.error(f"{path}.cable", name, "", "already has a load cell (one per cable)")
    bus = _cell_bus(rd, ct, path, cable, buses)
    node = rd.number(ct, "node_id", path, "", minimum=1, maximum=127, integer=True)
    tpdo = rd.number(ct, "tpdo", path, "", required=False, default=1, minimum=1, maximum=4,
                     integer=True)  # fmt: skip
    if node is not None and bus is not None:
        other = used.get((bus, int(node)))
        if other and other.startswith("the drive") and tpdo is not None and tpdo > 2:
            other = None  # a drive's analog input in its TPDO3/4 (cdprctl maps TPDO1-2)
        other = other or next(
            (f"the load cell of {names[c.cable]}" for c in cells
             if (c.bus, c.node_id) == (bus, int(node))), None)  # fmt: skip
        if other:
            rd.error(f"{path}.node_id", int(node), "", f"is already {other} on bus {bus}")
    obj = rd.number(ct, "object", path, "", required=False, default=0x9130, minimum=0x1000,
                    maximum=0xFFFF, integer=True)  # fmt: skip
    sub = rd.number(ct, "subindex", path, "", required=False, default=1, minimum=0,
                    maximum=254, integer=True)  # fmt: skip
    dtype = _cell_type(rd, ct, path, obj)
    scale = rd.number(ct, "scale", path, "N", positive=True)
    offset = rd.number(ct, "offset", path, "N", required=False, default=0.0)
    accuracy = rd.number(ct, "accuracy", path, "N", positive=True)
    timeout = rd.number(ct, "timeout", path, "s", required=False, default=0.03, positive=True,
                        maximum=0.1)  # fmt: skip
    vals = (cable, bus, node, obj, sub, dtype, tpdo, scale, offset, accuracy, timeout)
    if any(v is None for v in vals):
        return None
    return LoadCell(int(cable), int(bus), int(node), int(obj), int(sub), str(dtype), int(tpdo),  # type: ignore[arg-type]
                    float(scale), float(offset), float(accuracy), float(timeout))  # type: ignore[arg-type]  # fmt: skip


def _cell_bus(rd: TableReader, ct: dict[str, Any], path: str, cable: int | None,
              buses: tuple[BusConfig, ...]) -> int | None:  # fmt: skip
    """The cell's bus: ``bus`` (an index of [[drives.buses]]) or its cable's drive's."""
    if "bus" in ct:
        b = rd.number(ct, "bus", path, "", minimum=0, maximum=max(len(buses) - 1, 0),
                      integer=True)  # fmt: skip
        return None if b is None else int(b)
    if cable is None:
        return None
    return next((b for b, bus in enumerate(buses) if cable in bus.cables), 0)


def _cell_type(rd: TableReader, ct: dict[str, Any], path: str, obj: float | None) -> str | None:
    """``data_type``: given, or CiA 404's for its process-value objects."""
    default = CIA404_PV_TYPES.get(int(obj)) if obj is not None else None
    if "data_type" not in ct and default is None and obj is not None:
        rd.error_missing(f"{path}.data_type", "", f"for object 0x{int(obj):04X}, not one of "
                         "CiA 404's process values (0x6130, 0x7130, 0x9130): one of "
                         f"{', '.join(DATA_TYPES)}")  # fmt: skip
        return None
    s = rd.string(ct, "data_type", path, required=False, default=default)
    if s is not None and s not in DATA_TYPES:
        rd.error(f"{path}.data_type", s, "", f"must be one of {', '.join(DATA_TYPES)}")
        return None
    return s
