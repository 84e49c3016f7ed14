"""The load cells' tare (`cdprctl load-cells zero`) and its record: with the platform resting on
its stand and the cables unloaded, each cell's reading is its offset; kept as JSON in the
robot's state directory beside the calibration record (``load_cells.json``, written
atomically; a simulated robot's never where a real robot's records live) and applied by
`cdprctl run` to the driver's cells before the drives start (docs/homing.md, "Load cells").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.core.state_file import iso_utc, read_dataclass, write_json
from cdprctl.model.robot import RobotModel

FILE_NAME = "load_cells.json"
FORMAT = 1


class LoadCellError(Exception):
    """A tare that cannot be trusted, or a record that does not fit the robot: what and why."""


@dataclasses.dataclass
class LoadCellRecord:
    robot: str
    time: str  # ISO 8601, UTC
    offsets: dict[str, float]  # N per cable name: the tension at a value of 0
    std: dict[str, float]  # N per cable name: the readings' standard deviation in the tare
    samples: int  # readings averaged per cell
    simulated: bool = False  # taken on a simulated robot: never a real robot's record

    def check(self, model: RobotModel) -> None:
        """LoadCellError when the record is not this robot's cells'."""
        if self.robot != model.name:
            raise LoadCellError(f"the load cells' record is for robot {self.robot!r}, not "
                                f"{model.name!r}")  # fmt: skip
        cells = {model.cables[c.cable].name for c in model.sensors.load_cells}
        finite = all(math.isfinite(v) for v in self.offsets.values())
        if set(self.offsets) != cells or not finite:
            raise LoadCellError(
                f"the load cells' record of {self.time} has offsets for cables "
                f"{sorted(self.offsets)}, the robot cells on {sorted(cells)}"
            )


def tare(model: RobotModel, driver: Any, seconds: float, simulated: bool = False,
         log: Callable[[str], None] = print) -> LoadCellRecord:  # fmt: skip
    """Each cell read for ``seconds`` at the driver's period (the drives configured, not
    enabled): its offset the one that makes its mean reading 0 N. Refused (LoadCellError)
    for a cell that did not answer, or whose readings spread beyond its ``accuracy``: the
    platform is not at rest, or the cell is noisy."""
    cells = model.sensors.load_cells
    if not cells:
        raise LoadCellError(f"{model.name} has no load cells ([[sensors.load_cells]])")
    m = model.n_cables
    readings: list[np.ndarray] = []
    log(f"load cells: reading {len(cells)} cells for {seconds:g} s")
    for _ in range(max(1, round(seconds / driver.period))):
        st = driver.read(driver.clock())
        readings.append(st.tension[[c.cable for c in cells]].copy())
        driver.write(driver.clock(), np.zeros(m))
        driver.wait(driver.period)
    values = np.array(readings)  # N, with the file's offsets
    offsets, std = {}, {}
    for k, c in enumerate(cells):
        name = model.cables[c.cable].name
        v = values[:, k]
        if not np.all(np.isfinite(v)):
            raise LoadCellError(f"the load cell of cable {name} (node {c.node_id}) gave no value "
                                f"in {int(np.sum(~np.isfinite(v)))} of {len(v)} reads")  # fmt: skip
        if float(np.std(v)) > c.accuracy:
            raise LoadCellError(
                f"the load cell of cable {name} (node {c.node_id}) read {float(np.mean(v)):.2f} "
                f"N ± {float(np.std(v)):.2f} N, spread beyond its accuracy {c.accuracy:g} N: the "
                "platform is not at rest on its stand, or the cell is noisy"
            )  # fmt: skip
        offsets[name] = c.offset - float(np.mean(v))
        std[name] = float(np.std(v))
    return LoadCellRecord(model.name, iso_utc(), offsets, std, len(readings), simulated)


def record_path(state_dir: Path) -> Path:
    return Path(state_dir) / FILE_NAME


def save(record: LoadCellRecord, state_dir: Path) -> Path:
    """Written atomically (``state_file.write_json``)."""
    return write_json(record_path(state_dir), FORMAT, record)


def load(state_dir: Path) -> LoadCellRecord:
    """The record in ``state_dir``; LoadCellError saying what is wrong."""
    return read_dataclass(LoadCellRecord, record_path(state_dir), FORMAT, "load cells' record",
                          LoadCellError)  # fmt: skip


def apply(record: LoadCellRecord, model: RobotModel, driver: Any) -> None:
    """The record's offsets to the driver's cells (checked against the robot first)."""
    record.check(model)
    names = [c.name for c in model.cables]
    driver.cells.apply_offsets({names.index(n): v for n, v in record.offsets.items()})
