"""The CiA 402 set-up's rules (``drivers/cia402/drive_setup.configure_drive``) against a
dictionary-backed drive that answers as CiA 301's SDO server would (values by their size,
unsigned on the wire; aborts by code): what a static mapping, a DCF, a refused or optional
write and a drive in another mode make of the start."""

from __future__ import annotations

import pytest

from drivers.cia402 import drive_setup as ds
from drivers.cia402 import pdo_setup as ps
from drivers.cia402 import protocol as p
from drivers.cia402.capabilities import Capabilities
from drivers.errors import DriverInitializationError, SdoAbortError
from sim_backend.drives.dictionary import EDS

NODE = 3
RATED = 1.2  # N·m, [drives] rated_torque


class Drive:
    """An object dictionary: (index, sub) → (value, size in bytes). ``refuse``: (index, sub) →
    abort code of every write there; 0x6061 shows 0x6060 unless ``shown`` says otherwise."""

    def __init__(self, refuse: dict | None = None, shown: int | None = None):
        self.od: dict[tuple[int, int], tuple[int, int]] = {
            (p.OD_PRODUCER_HEARTBEAT, 0): (0, 2), (p.OD_RATED_TORQUE, 0): (1200, 4),
            (p.OD_MODES_OF_OPERATION, 0): (0, 1), (p.OD_ABORT_CONNECTION, 0): (1, 2),
            (p.OD_MAX_TORQUE, 0): (3000, 2), (p.OD_SYNC_COUNTER_OVERFLOW, 0): (0, 1),
            (p.OD_FOLLOWING_ERROR_WINDOW, 0): (0, 4), (p.OD_FOLLOWING_ERROR_TIMEOUT, 0): (0, 2),
            (0x6065, 0): (0, 4), (0x1800, 3): (0, 2),
        }  # fmt: skip
        for pdo in ps.wanted(p.MODE_CSP, NODE, True):  # already as cdprctl wants them
            self.od[(pdo.comm, 1)] = (pdo.cob_id, 4)
            self.od[(pdo.comm, 2)] = (1, 1)
            self.od[(pdo.mapping, 0)] = (len(pdo.entries), 1)
            self.od.update({(pdo.mapping, k): (e, 4) for k, e in enumerate(pdo.entries, 1)})
        self.refuse, self.shown = refuse or {}, shown
        self.writes: list[tuple[int, int, int]] = []

    def read(self, c: int, index: int, sub: int, timeout: float, signed: bool = True) -> int:
        if index == p.OD_MODES_DISPLAY and sub == 0:
            return self.od[(p.OD_MODES_OF_OPERATION, 0)][0] if self.shown is None else self.shown
        if (index, sub) not in self.od:
            raise SdoAbortError("no object", NODE, index, sub, p.SDO_ABORT_NO_OBJECT)
        value, size = self.od[(index, sub)]
        return int.from_bytes(value.to_bytes(size, "little"), "little", signed=signed)

    def write(self, c: int, index: int, sub: int, value: int, size: int, timeout: float) -> None:
        if (index, sub) in self.refuse:
            raise SdoAbortError("refused", NODE, index, sub, self.refuse[(index, sub)])
        self.writes.append((index, sub, value))
        self.od[(index, sub)] = (value % (1 << 8 * size), size)

    def value(self, index: int, sub: int = 0) -> int:
        return self.od[(index, sub)][0]


def set_up(drive: Drive, *, dcf: str | None = None, rated: int | None = 1200,
           pdo_mapping: str = "configure", heartbeat: float = 0.5) -> ds.DriveRecord:  # fmt: skip
    """``configure_drive`` on cable index 0 (node 3, csp, velocity by TPDO2) against ``drive``;
    ``rated``: 0x6076 as the capabilities read it before (mN·m). Returns what it recorded."""
    plan = ds.DrivePlan(
        cable=0, node=NODE, mode=p.MODE_CSP, dcf=dcf or "",
        heartbeat_ms=round(heartbeat * 1000 / 5), rated_torque=RATED, max_torque_pm=2500,
        following_window=400, following_timeout_ms=3,
        configure_pdos=pdo_mapping == "configure", velocity_pdo=True,
    )  # fmt: skip
    record = ds.DriveRecord()
    caps = Capabilities(None, 0x00020192, 1 << 7, rated, present={})
    ds.configure_drive(drive, plan, record, 0.1, caps, True)  # type: ignore[arg-type]
    return record


def test_a_drive_set_up_as_wanted_gets_only_cdprctls_settings():
    drive = Drive()
    drv = set_up(drive)
    assert drv.pdos_written == 0 and drv.skipped == []
    assert drive.value(p.OD_MODES_OF_OPERATION) == p.MODE_CSP
    assert drive.value(p.OD_PRODUCER_HEARTBEAT) == 100  # 0.5 s / 5, ms
    assert drive.value(p.OD_FOLLOWING_ERROR_TIMEOUT) == 3  # ms
    assert drive.value(p.OD_FOLLOWING_ERROR_WINDOW) == 400
    assert drive.value(p.OD_MAX_TORQUE) == 2500


def test_a_drive_whose_heartbeat_is_not_cdprctls_was_reset_since_its_last_set_up():
    """0x1017 is a communication object a reset restores (CiA 301 §7.3.2): found other than
    what cdprctl writes, the drive was reset (the homing it held is gone); found as written,
    it was not."""
    drive = Drive()
    assert set_up(drive).reset is True  # 0: the drive's default
    assert set_up(drive).reset is False  # as the first set-up left it
    assert set_up(drive, heartbeat=0.6).reset is True


def test_a_static_mapping_that_differs_refuses_the_start_and_writes_no_pdo():
    drive = Drive()
    tpdo1 = ps.wanted(p.MODE_CSP, NODE, True)[1]
    drive.od[(tpdo1.comm, 2)] = (255, 1)  # event-driven (CiA 301 Table 72)
    with pytest.raises(DriverInitializationError) as exc:
        set_up(drive, pdo_mapping="static")
    assert "TPDO1 is not what cdprctl's codec needs" in str(exc.value)
    assert "transmission type expected 1 (every SYNC), found 255" in str(exc.value)  # unsigned
    assert drive.writes == []


def test_a_configured_mapping_that_differs_is_written():
    drive = Drive()
    tpdo1 = ps.wanted(p.MODE_CSP, NODE, True)[1]
    drive.od[(tpdo1.comm, 2)] = (255, 1)
    assert set_up(drive).pdos_written == 1
    assert drive.value(tpdo1.comm, 2) == 1


@pytest.mark.parametrize("shown", [p.MODE_CSP - 1, p.MODE_CSP + 1, 0])
def test_a_drive_that_shows_another_mode_than_written_refuses_the_start(shown):
    with pytest.raises(DriverInitializationError) as exc:
        set_up(Drive(shown=shown))
    assert str(exc.value) == (
        f"drive of cable index 0 (node 3) reports mode {shown} in 0x6061, "
        "expected 8 (cyclic synchronous position, [drives] mode)")  # fmt: skip


@pytest.mark.parametrize(("index", "why"), [
    (p.OD_MODES_OF_OPERATION, "cyclic synchronous position, [drives] mode"),
    (p.OD_PRODUCER_HEARTBEAT, "its heartbeat, how cdprctl knows it is there"),
])  # fmt: skip
def test_a_needed_object_the_drive_refuses_stops_the_start_by_name(index, why):
    """Not the bare SDO abort: the set-up's own error, naming drive, object, value and why."""
    with pytest.raises(DriverInitializationError) as exc:
        set_up(Drive(refuse={(index, 0): 0x06090030}))
    assert type(exc.value) is DriverInitializationError
    value = 8 if index == p.OD_MODES_OF_OPERATION else 100
    assert str(exc.value).startswith(
        f"drive of cable index 0 (node 3): refused 0x{index:04X} := {value} ({why}): "), exc.value
    assert str(exc.value).endswith("(0x06090030)")


# CiA 301 Table 22: object does not exist, sub-index does not exist, read-only, data type /
# length does not match, value range exceeded, value too high, value too low (written out:
# not the module's own set, which a wrong code in it would change alike)
SKIPPABLE = (0x06020000, 0x06090011, 0x06010002, 0x06070010, 0x06090030, 0x06090031, 0x06090032)


@pytest.mark.parametrize("code", SKIPPABLE)
@pytest.mark.parametrize("index", sorted(ds.OPTIONAL))
def test_an_optional_object_refused_as_absent_read_only_or_out_of_range_is_skipped(index, code):
    drv = set_up(Drive(refuse={(index, 0): code}))
    (line,) = drv.skipped
    assert line.startswith(f"0x{index:04X} {ds.OPTIONAL[index][0]} := "), line
    assert f"(0x{code:08X})" in line
    assert line.endswith(ds.OPTIONAL[index][1])


@pytest.mark.parametrize("code", [0x06010000, 0x08000020, 0x08000022, 0x0607000F, 0x06070011,
                                  0x0609002F, 0x06090033])  # fmt: skip
def test_an_optional_object_refused_for_any_other_reason_stops_the_start(code):
    """Access, state, transfer: not a drive without the object (CiA 301 Table 22)."""
    with pytest.raises(SdoAbortError) as exc:
        set_up(Drive(refuse={(p.OD_MAX_TORQUE, 0): code}))
    assert exc.value.code == code


def test_a_drive_without_a_rated_torque_is_noted_with_the_configs():
    drv = set_up(Drive(), rated=None)
    assert drv.skipped == ["0x6076 motor rated torque: the drive has none to check; torques in "
                           "per mille of 1200 mN·m ([drives] rated_torque) as the config says"]


def test_a_rated_torque_other_than_the_configs_refuses_the_start():
    with pytest.raises(DriverInitializationError) as exc:
        set_up(Drive(), rated=1000)
    assert "rated torque 0x6076 is 1000 mN·m, the config says 1200 mN·m" in str(exc.value)


def dcf(tmp_path, values: dict[str, int]) -> str:
    """The shipped EDS as a DCF with ParameterValue lines in the sections named."""
    text = EDS.read_text()
    for section, value in values.items():
        text = text.replace(f"[{section}]\n", f"[{section}]\nParameterValue=0x{value:X}\n")
    path = tmp_path / "winch.dcf"
    path.write_text(text)
    return str(path)


def test_a_dcfs_values_are_written_first_and_cdprctls_own_settings_win(tmp_path):
    drive = Drive()
    set_up(drive, dcf=dcf(tmp_path, {"1800sub3": 7, "1017": 999}))
    assert (0x1800, 3, 7) in drive.writes and drive.value(0x1800, 3) == 7
    heartbeats = [w[2] for w in drive.writes if w[:2] == (p.OD_PRODUCER_HEARTBEAT, 0)]
    assert heartbeats == [999, 100]


def test_with_a_dcf_the_rated_torque_is_read_after_it_is_written(tmp_path):
    """A DCF may set the motor's data: 0x6076 is judged as the DCF left it, not as the
    capabilities read it before (0 there: unset)."""
    set_up(Drive(), dcf=dcf(tmp_path, {"6076": 1200}), rated=0)
    with pytest.raises(DriverInitializationError, match="rated torque 0x6076 is 900 mN·m"):
        set_up(Drive(), dcf=dcf(tmp_path, {"6076": 900}), rated=1200)


def test_a_dcf_value_the_drive_refuses_stops_the_start_by_name(tmp_path):
    path = dcf(tmp_path, {"1800sub3": 7})
    with pytest.raises(DriverInitializationError) as exc:
        set_up(Drive(refuse={(0x1800, 3): 0x06090030}), dcf=path)
    assert type(exc.value) is DriverInitializationError
    assert str(exc.value) == (f"drive of cable index 0 (node 3): refused 0x1800:03 := 7 from "
                              f"{path} (SDO abort 0x06090030)")  # fmt: skip
