"""The ``[[sensors.load_cells]]`` section: each rule refused with the key, the value, the unit
and the rule; a robot file without it unchanged."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import CONFIG

from cdprctl.model import ConfigError
from cdprctl.robot_file import load_robot

CELL = """
[[sensors.load_cells]]
cable = "1"
node_id = 21
scale = 0.01
accuracy = 0.5
"""


def load(tmp_path: Path, extra: str):
    p = tmp_path / "cells.toml"
    p.write_text(f'base = "{CONFIG / "rowc.toml"}"\n' + extra)
    return load_robot(p)


def errors(tmp_path: Path, extra: str) -> list[str]:
    with pytest.raises(ConfigError) as exc:
        load(tmp_path, extra)
    return exc.value.errors


def test_example_file_has_a_cell_per_cable_and_rowc_none():
    m = load_robot(CONFIG / "rowc_load_cells.toml")
    cells = m.sensors.load_cells
    assert [c.cable for c in cells] == list(range(8))
    # each on its winch's bus (rowc: cables 1-4 on bus 0, 5-8 on bus 1), CiA 404's INTEGER32
    assert [c.bus for c in cells] == [0] * 4 + [1] * 4
    assert {(c.object, c.subindex, c.data_type) for c in cells} == {(0x9130, 1, "int32")}
    assert cells[0].cob_id == 0x180 + 21
    assert m.sensors.cell_of(3) is cells[3]
    assert load_robot(CONFIG / "rowc.toml").sensors.load_cells == ()


def test_defaults_and_types(tmp_path):
    m = load(tmp_path, CELL.replace("node_id = 21", "node_id = 21\nobject = 0x6130\ntpdo = 2"))
    c = m.sensors.load_cells[0]
    assert (c.data_type, c.tpdo, c.cob_id, c.offset, c.timeout) == ("real32", 2, 0x280 + 21,
                                                                    0.0, 0.03)  # fmt: skip


@pytest.mark.parametrize(
    "change, expected",
    [
        (('cable = "1"', 'cable = "9"'), 'sensors.load_cells[0].cable = \'9\' is not a cable'),
        (("node_id = 21", "node_id = 3"),
         "sensors.load_cells[0].node_id = 3 is already the drive of 3 on bus 0"),
        (("node_id = 21", "node_id = 3\ntpdo = 2"),
         "sensors.load_cells[0].node_id = 3 is already the drive of 3 on bus 0"),
        (("node_id = 21", "node_id = 127"),
         "node_id = 127 is already the controller (drives.controller_node_id) on bus 0"),
        (("scale = 0.01", "scale = -0.01"), "sensors.load_cells[0].scale = -0.01 N must be > 0"),
        (("accuracy = 0.5", ""), "sensors.load_cells[0].accuracy is missing"),
        (("node_id = 21", "node_id = 21\nobject = 0x2205"),
         "sensors.load_cells[0].data_type is missing: required, for object 0x2205"),
        (("node_id = 21", 'node_id = 21\ndata_type = "float64"'),
         "data_type = 'float64' must be one of int16, int32, real32"),
        (("node_id = 21", "node_id = 21\ntimeout = 0.5"),
         "sensors.load_cells[0].timeout = 0.5 s must be <= 0.1"),
        (("node_id = 21", "node_id = 21\ntpdo = 5"), "sensors.load_cells[0].tpdo = 5 must be <= 4"),
        (("node_id = 21", "node_id = 21\nbus = 2"), "sensors.load_cells[0].bus = 2 must be <= 1"),
        (("scale = 0.01", "scale = 0.01\nscael = 1"),
         "scael is not a known key (did you mean scale?"),
    ],
)  # fmt: skip
def test_bad_cell_is_named(tmp_path, change, expected):
    errs = errors(tmp_path, CELL.replace(*change))
    assert any(expected in e for e in errs), errs


def test_a_drives_analog_input_in_its_tpdo3(tmp_path):
    """A drive's own analog input: its node, a TPDO cdprctl does not map (3 or 4), its
    object and data type."""
    cell = CELL.replace(
        "node_id = 21", 'node_id = 1\ntpdo = 3\nobject = 0x2205\ndata_type = "int16"'
    )
    c = load(tmp_path, cell).sensors.load_cells[0]
    assert (c.node_id, c.cob_id, c.object, c.data_type) == (1, 0x381, 0x2205, "int16")


def test_two_cells_on_one_cable_or_node(tmp_path):
    errs = errors(tmp_path, CELL + CELL)
    assert any("cable = '1' already has a load cell" in e for e in errs), errs
    assert any("node_id = 21 is already the load cell of 1 on bus 0" in e for e in errs), errs
    # the same node id on the other bus is another node
    m = load(tmp_path, CELL + CELL.replace('"1"', '"5"'))
    assert [(c.bus, c.node_id) for c in m.sensors.load_cells] == [(0, 21), (1, 21)]


def test_section_keys(tmp_path):
    errs = errors(tmp_path, "[sensors]\nestimate_error = 0\ndisagreement_time = 0.2\n")
    assert any("sensors.estimate_error = 0 N must be > 0" in e for e in errs), errs
    assert any("sensors.disagreement_time = 0.2 s must be <= 0.1" in e for e in errs), errs


def test_refused_on_odrive_buses(tmp_path):
    p = tmp_path / "odrive_cells.toml"
    p.write_text(f'base = "{CONFIG / "rowc_odrive.toml"}"\n' + CELL)
    with pytest.raises(ConfigError) as exc:
        load_robot(p)
    assert any("sensors.load_cells = '1 cells' need CANopen buses" in e
               for e in exc.value.errors), exc.value.errors  # fmt: skip


def test_the_cells_count_in_the_bus_load():
    """Each cell's TPDO (4 bytes for 0x9130) in its bus's budget: rowc's four cells a bus at
    250 Hz add 4 × frame_bits(4) × 250 bit/s, against the drives' frames alone."""
    from drivers.busload import bus_loads, frame_bits

    m = load_robot(CONFIG / "rowc_load_cells.toml")
    without = bus_loads(m.drives, 250.0)
    with_cells = bus_loads(m.drives, 250.0, cells=m.sensors.load_cells)
    for a, b in zip(without, with_cells, strict=True):
        assert b.bits_per_cycle - a.bits_per_cycle == 4 * frame_bits(4)
        assert "4 x load cell TPDO (4 B)" in b.frames
        assert b.load == pytest.approx(a.load + 4 * frame_bits(4) * 250.0 / b.bitrate)
