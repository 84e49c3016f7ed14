"""A load cell as the simulator's CAN node: a CiA 404 measuring device with one analog input
(``cdprctl_load_cell.eds``), measuring its cable's tension in the plant.

CiA 301 as the drives have it (``cia402.py``): NMT, the boot-up message, heartbeat production
(0x1017), the object dictionary served by canopen's SDO server (``dictionary.py``), the TPDOs
as their communication and mapping objects say (``pdo.layout``; CiA 301's checks of a write,
``pdo.check_write``), sampled at the SYNC in OPERATIONAL. CiA 404's analog input: the process
value in newtons (0x6131) as REAL32 (0x6130) and, with the decimal digits of 0x6132, as
INTEGER16 (0x7130, saturated) and INTEGER32 (0x9130); 0x6150 its status.

What a real cell gets wrong, each settable (``sim_backend/faults.py`` injects them): an
``offset`` (N: what `cdprctl load-cells zero` measures), a ``gain`` error (the scale the
statics check), ``noise`` (N, standard deviation of each sample, seeded), a ``drift_rate``
(N/s: a creeping bridge or a loose connector), and a dead cell (``silent``: nothing sent).
"""

from __future__ import annotations

import math
import random
from pathlib import Path

import can

from cdprctl.model.robot import RobotModel
from cdprctl.model.sensors import LoadCell
from drivers.cia402 import protocol as p
from sim_backend.drives import pdo
from sim_backend.drives.dictionary import NMT_RESETS, NMT_STATE_OF, Dictionary
from sim_backend.plant import CdprPlant

EDS = Path(__file__).with_name("cdprctl_load_cell.eds")
TPDO_COMMS = (0x1800, 0x1801, 0x1802, 0x1803)
AI_PV_REAL32, AI_PV_INT16, AI_PV_INT32 = 0x6130, 0x7130, 0x9130
AI_DECIMAL_DIGITS, AI_STATUS = 0x6132, 0x6150
#: N: the standard deviation of a simulated cell's samples (a 500 N cell's 0.02 % noise)
DEFAULT_NOISE = 0.1


class LoadCellNode:
    def __init__(self, node_id: int, cable: int, plant: CdprPlant, seed: int = 0,
                 noise: float = DEFAULT_NOISE):  # fmt: skip
        self.node_id, self.cable, self.plant = node_id, cable, plant
        self.nmt = p.HB_PRE_OPERATIONAL
        self.dictionary = Dictionary(node_id, {}, self._read_object, self._check_object,
                                     self._object_written, eds=EDS)  # fmt: skip
        self.od = self.dictionary.values
        self.offset = 0.0  # N
        self.gain = 1.0
        self.noise = noise  # N
        self.drift_rate = 0.0  # N/s
        self.drift = 0.0  # N, accumulated
        self.silent = False
        self.rng = random.Random(seed)
        self.sample = 0.0  # N: the reading at the last SYNC
        self.last_hb = -math.inf
        self.last_tick = math.nan
        self.tx: list[pdo.Layout] = []
        self.tx_count = [0] * len(TPDO_COMMS)
        self.compile()

    def reading(self) -> float:
        """N: what the cell reads now (its errors on the plant's tension)."""
        t = float(self.plant.tension[self.cable])
        return self.gain * t + self.offset + self.drift + self.noise * self.rng.gauss(0.0, 1.0)

    def compile(self) -> None:
        """The TPDOs from their objects (after a write or a reset)."""
        self.tx = [pdo.layout(self.dictionary.od, self.od, comm) for comm in TPDO_COMMS]

    # -- frames in ------------------------------------------------------------------------------
    def on_nmt(self, command: int) -> list[can.Message]:
        """NMT (CiA 301 §7.3.2); a reset restores the objects and ends with the boot-up."""
        if command in NMT_STATE_OF:
            self.nmt = NMT_STATE_OF[command]
        elif command in NMT_RESETS:
            self.dictionary.reset_by(command)
            self.compile()
            self.nmt = p.HB_PRE_OPERATIONAL
            self.last_hb = -math.inf
            return self.boot_up()
        return []

    def on_sdo(self, data: bytes) -> can.Message | None:
        if len(data) != 8 or self.silent or self.nmt == p.HB_STOPPED:
            return None
        return self.dictionary.request(p.SDO_RX + self.node_id, data)

    def on_sync(self, t: float, data: bytes = b"") -> list[can.Message]:
        """Sample the input; the TPDOs due (transmission type n: every n-th SYNC)."""
        if self.nmt != p.HB_OPERATIONAL:
            return []
        self.sample = self.reading()
        value = self.dictionary.value
        out = pdo.due_tpdos(self.tx, self.tx_count,
                            lambda _, tx: [value(index, sub) for index, sub in tx.entries])
        return [] if self.silent else out

    def tick(self, t: float) -> list[can.Message]:
        """The drift accumulated; the heartbeat when due."""
        if math.isfinite(self.last_tick):
            self.drift += self.drift_rate * max(t - self.last_tick, 0.0)
        self.last_tick = t
        hb_ms = self.od[(p.OD_PRODUCER_HEARTBEAT, 0)]
        if hb_ms > 0 and not self.silent and t - self.last_hb >= hb_ms / 1000.0 - 1e-9:
            self.last_hb = t
            return [self._heartbeat(self.nmt)]
        return []

    def boot_up(self) -> list[can.Message]:
        return [] if self.silent else [self._heartbeat(p.HB_BOOTUP)]

    def _heartbeat(self, state: int) -> can.Message:
        return can.Message(arbitration_id=p.HEARTBEAT + self.node_id, data=bytes([state]),
                           is_extended_id=False)  # fmt: skip

    # -- the dictionary's hooks -----------------------------------------------------------------
    def _read_object(self, index: int, sub: int) -> float | int | None:
        """The process value (an SDO upload or a TPDO): the last sample, in N (REAL32) or in
        units of 10^-digits N (the integers, saturated to their range)."""
        if sub != 1:
            return None
        if index == AI_PV_REAL32:
            return self.sample
        if index in (AI_PV_INT16, AI_PV_INT32):
            bits = 15 if index == AI_PV_INT16 else 31
            scaled = round(self.sample * 10.0 ** self.od[(AI_DECIMAL_DIGITS, 1)])
            return max(-(1 << bits), min((1 << bits) - 1, scaled))
        if index == AI_STATUS:
            return 0  # bit 0: not valid, 1-2: over/under range; the simulated input never is
        return None

    def _check_object(self, index: int, sub: int, value: int) -> None:
        if pdo.is_pdo_object(index):
            operational = self.nmt == p.HB_OPERATIONAL
            pdo.check_write(self.dictionary.od, self.od, operational, index, sub, value)

    def _object_written(self, index: int, sub: int, value: int) -> None:
        if pdo.is_pdo_object(index):
            self.compile()


def load_cell_nodes(model: RobotModel, plant: CdprPlant) -> list[tuple[LoadCell, LoadCellNode]]:
    """The robot's load cells (``[[sensors.load_cells]]``) as simulated nodes, each seeded by
    its node id and bus."""
    return [(c, LoadCellNode(c.node_id, c.cable, plant, seed=1000 * c.bus + c.node_id))
            for c in model.sensors.load_cells]  # fmt: skip
