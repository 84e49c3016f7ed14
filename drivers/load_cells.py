"""The load cells' read side and set-up (``[[sensors.load_cells]]``): each cell's process value
from its TPDO, into the winches' ``tension`` (N) and ``tension_age`` (s), and the set-up that
checks each cell — and maps its TPDO — by SDO as the drives' is (docs/drivers.md, "Load
cells").

A cell's TPDO is taken whole into a slot of preallocated bytes as it is drained; once a cycle
``cells_kernel`` decodes the fresh ones (INTEGER16, INTEGER32 or REAL32 at the value's place
in the PDO), scales them (``tension = scale · value + offset``) and ages them: a cell silent
for longer than its ``timeout`` reads NaN, which the control side takes as no cell
(``cdprctl/control/cycle/tension_source.py``, where a dead cell is a fault). The driver itself never
fails on a cell: a cell is a better tension, not a condition for driving.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cdprctl.core.numerics import cycle_kernel
from cdprctl.model.sensors import CIA404_PV_TYPES, DATA_SIZES, DATA_TYPES, LoadCell
from drivers.cia402 import protocol as p
from drivers.errors import DriverInitializationError
from drivers.vocabulary import WinchStates

#: the dispatch table's kind of a load cell's TPDO (the drives' are 1-5: cia402/feedback.py)
LOAD_CELL = 6
CIA404_PROFILE = 404  # 0x1000 bits 0-15 of a CiA 404 measuring device
PDO_NOT_VALID = 0x80000000
SYNC_EVERY = 1  # transmission type: a TPDO at every SYNC


class LoadCells:
    """The cells of a robot (``cells``) on a driver's buses, with their decoding state."""

    def __init__(self, cells: tuple[LoadCell, ...], m: int, states: WinchStates):
        self.cells = cells
        n = len(cells)
        self.states = states
        self.cable = np.array([c.cable for c in cells], dtype=np.int64)
        self.bus = np.array([c.bus for c in cells], dtype=np.int64)
        self.node = np.array([c.node_id for c in cells], dtype=np.int64)
        self.sdo_index = [0] * n  # each cell's index for the set-up's SDO client
        self.type_code = np.array([DATA_TYPES.index(c.data_type) for c in cells], dtype=np.int64)
        self.place = np.zeros(n, dtype=np.int64)  # byte of the value in its TPDO (set-up)
        self.scale = np.array([c.scale for c in cells])  # N per unit
        # N: the file's offset, or the calibration record's (``apply_offsets``)
        self.offset = np.array([c.offset for c in cells])
        self.timeout = np.array([c.timeout for c in cells])  # s
        self.frames = bytearray(8 * max(n, 1))  # each cell's last TPDO, as received
        self.raw = np.frombuffer(self.frames, dtype=np.uint8).reshape(max(n, 1), 8)
        self.fresh = np.zeros(n, dtype=bool)
        self.stamp = np.full(n, -math.inf)  # s: when each cell's last value came
        self.value = np.full(n, math.nan)  # N: each cell's last tension
        self.bits = np.zeros(1, dtype=np.uint32)  # a REAL32's bits, and the float they are
        self.real = self.bits.view(np.float32)
        states.tension[:] = math.nan

    def dispatch_into(self, dispatch: dict[tuple[int, int], tuple[int, int]], m: int,
                      sdo_kind: int) -> None:  # fmt: skip
        """Each cell's TPDO (kind ``LOAD_CELL``, its index) and SDO answers (``sdo_kind``,
        index ``m + k``: the set-up's SDO port numbers the cells after the ``m`` drives)."""
        for k, c in enumerate(self.cells):
            dispatch[(c.bus, c.cob_id)] = (LOAD_CELL, k)
            drive = dispatch.get((c.bus, p.SDO_TX + c.node_id))
            # a drive's own analog input: its SDO answers are the drive's
            self.sdo_index[k] = drive[1] if drive is not None else m + k
            if drive is None:
                dispatch[(c.bus, p.SDO_TX + c.node_id)] = (sdo_kind, m + k)

    def receive(self, k: int, data: Any) -> None:
        """Cell ``k``'s TPDO (bytes): kept for the cycle's decoding."""
        n = len(data)
        if n <= 8:
            self.frames[8 * k : 8 * k + n] = data
            self.fresh[k] = True

    def update(self, t: float) -> None:
        """The cycle's decoding and ages, at ``t`` (s), into the states."""
        cells_kernel(self.raw, self.place, self.type_code, self.scale, self.offset, self.fresh,
                     self.stamp, self.value, t, self.timeout, self.cable, self.bits, self.real,
                     self.states.tension, self.states.tension_age)  # fmt: skip

    def all_heard(self) -> bool:
        """Every cell has sent a value (the set-up waits for it as for the drives')."""
        return bool(np.all(np.isfinite(self.stamp)))

    def apply_offsets(self, offsets: dict[int, float]) -> None:
        """The offsets (N, by cable index) of the calibration record (`load-cells zero`)."""
        for k, c in enumerate(self.cells):
            if c.cable in offsets:
                self.offset[k] = offsets[c.cable]

    def warm_up(self) -> None:
        """The kernel once, on copies (compiled before the drives start)."""
        n = len(self.cells)
        cells_kernel(self.raw.copy(), self.place, self.type_code, self.scale, self.offset,
                     np.ones(n, dtype=bool), self.stamp.copy(), self.value.copy(), 0.0,
                     self.timeout, self.cable, self.bits.copy(), self.bits.copy().view(np.float32),
                     self.states.tension.copy(), self.states.tension_age.copy())  # fmt: skip

    # -- set-up ---------------------------------------------------------------------------------
    def configure(self, sdo: Any, configure: bool, timeout: float) -> None:
        """Each cell checked by SDO in PRE-OPERATIONAL (``sdo``: the client whose port numbers
        cell ``k`` ``sdo_index[k]``: after the drives, or a drive's own): a CiA 404 device
        where its object is one of CiA 404's; its TPDO
        at every SYNC carrying the value — mapped so when ``configure`` ([drives] pdo_mapping),
        else refused. DriverInitializationError names the cell and the fix."""
        for k, cell in enumerate(self.cells):
            where = f"load cell of cable index {cell.cable} (node {cell.node_id}, bus {cell.bus})"
            try:
                self.place[k] = _setup_cell(sdo, self.sdo_index[k], cell, configure, timeout,
                                            where)  # fmt: skip
            except DriverInitializationError:
                raise
            except Exception as exc:  # a timeout, an abort: said with the cell
                raise DriverInitializationError(f"{where}: {exc}") from exc


def _setup_cell(sdo: Any, i: int, cell: LoadCell, configure: bool, timeout: float,
                where: str) -> int:  # fmt: skip
    """Cell ``cell`` (SDO index ``i``) checked and mapped; the byte its value takes in its
    TPDO."""
    if cell.object in CIA404_PV_TYPES:
        profile = sdo.read(i, p.OD_DEVICE_TYPE, 0, timeout, signed=False) & 0xFFFF
        if profile != CIA404_PROFILE:
            raise DriverInitializationError(
                f"{where}: device type (0x1000) says profile {profile}, not CiA 404's measuring "
                f"device: object 0x{cell.object:04X} is CiA 404's; a drive's analog input is "
                "another object, given with its data_type (docs/config.md, 'Load cells')"
            )
    comm, mapping = 0x1800 + cell.tpdo - 1, 0x1A00 + cell.tpdo - 1
    cob = sdo.read(i, comm, 1, timeout, signed=False)
    if cob & 0x7FF != cell.cob_id:
        raise DriverInitializationError(
            f"{where}: TPDO{cell.tpdo}'s COB-ID (0x{comm:04X}:01) is 0x{cob & 0x7FF:03X}, not "
            f"0x{cell.cob_id:03X} (0x180 + 0x100 (tpdo - 1) + node): set the node id or tpdo"
        )
    place = _mapped_at(sdo, i, mapping, cell, timeout)
    kind = sdo.read(i, comm, 2, timeout, signed=False)
    if place >= 0 and kind == SYNC_EVERY and not cob & PDO_NOT_VALID:
        return place
    if not configure:
        raise DriverInitializationError(
            f"{where}: TPDO{cell.tpdo} does not carry 0x{cell.object:04X}:{cell.subindex:02X} "
            f"at every SYNC (valid {not cob & PDO_NOT_VALID}, transmission type {kind}, "
            f"mapped {place >= 0}) and [drives] pdo_mapping = 'static' writes nothing: map it "
            "with the vendor's tool, or pdo_mapping = 'configure'"
        )
    bits = 8 * DATA_SIZES[cell.data_type]
    sdo.write(i, comm, 1, cob | PDO_NOT_VALID, 4, timeout)  # disabled while it changes
    sdo.write(i, mapping, 0, 0, 1, timeout)
    sdo.write(i, mapping, 1, (cell.object << 16) | (cell.subindex << 8) | bits, 4, timeout)
    sdo.write(i, mapping, 0, 1, 1, timeout)
    sdo.write(i, comm, 2, SYNC_EVERY, 1, timeout)
    sdo.write(i, comm, 1, cell.cob_id, 4, timeout)
    return 0


def _mapped_at(sdo: Any, i: int, mapping: int, cell: LoadCell, timeout: float) -> int:
    """The byte of the cell's value in its TPDO as mapped (-1: not mapped, or with another
    size than its data type's)."""
    place = 0
    for s in range(1, sdo.read(i, mapping, 0, timeout, signed=False) + 1):
        entry = sdo.read(i, mapping, s, timeout, signed=False)
        index, sub, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        if (index, sub) == (cell.object, cell.subindex):
            return place if bits == 8 * DATA_SIZES[cell.data_type] else -1
        place += bits // 8
    return -1


@cycle_kernel
def cells_kernel(raw, place, type_code, scale, offset, fresh, stamp, value, t, timeout, cable,
                 bits, real, tension, age):  # pragma: no cover - compiled  # fmt: skip
    """Per cell ``k``: a fresh TPDO ``raw[k]`` decoded at byte ``place[k]`` (``type_code``:
    the index in ``DATA_TYPES``: int16, int32, real32, little-endian), ``value[k]`` ← ``scale
    · v + offset`` (N) stamped ``t``; then its cable's ``tension`` (N; NaN once silent beyond
    ``timeout[k]`` s) and ``age`` (s). ``bits``/``real``: one uint32 and its float32 view."""
    for k in range(cable.shape[0]):
        if fresh[k]:
            fresh[k] = False
            o = place[k]
            u = np.int64(raw[k, o]) | (np.int64(raw[k, o + 1]) << 8)
            if type_code[k] == 0:
                v = float(u - 65536 if u >= 32768 else u)
            else:
                u |= (np.int64(raw[k, o + 2]) << 16) | (np.int64(raw[k, o + 3]) << 24)
                if type_code[k] == 1:
                    v = float(u - 4294967296 if u >= 2147483648 else u)
                else:
                    bits[0] = u
                    v = float(real[0])
            if math.isfinite(v):
                value[k] = scale[k] * v + offset[k]
                stamp[k] = t
        c = cable[k]
        age[c] = t - stamp[k]
        tension[c] = value[k] if age[c] <= timeout[k] else math.nan
