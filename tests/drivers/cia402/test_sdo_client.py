"""The set-up's SDO client (``drivers/cia402/sdo_client.py``) against a scripted drive on a
simulated clock: the expedited upload's size bits (CiA 301 §7.2.4.3.3: n bytes at the end
hold no data, whatever the drive puts there), a lost request sent again every ``RETRY`` and
no more often, the time-out when the drive stays silent, an abort naming its object."""

from __future__ import annotations

import itertools
import struct

import pytest

from drivers.cia402 import protocol as p
from drivers.cia402.sdo_client import SdoClient
from drivers.errors import DriverInitializationError, DriverTimeoutError, SdoAbortError


class ScriptedDrive:
    """An ``SdoPort`` (the part of a CAN driver the SDO client uses) with a clock that
    ``wait`` advances and a drive that answers each request by ``answer(request) -> bytes |
    None`` (None: silent)."""

    def __init__(self, answer):
        self.answer = answer
        self.now = 0.0
        self.period = 0.004
        self.bus_of = [0, 0]
        self.node = [1, 2]
        self.media = [0]
        self.replies: dict[int, bytes] = {}
        self.sent: list[tuple[float, bytes]] = []

    def clock(self) -> float:
        return self.now

    def wait(self, dt: float) -> None:
        self.now += dt
        if self.now > 10.0:  # every time-out here is shorter: the client missed it
            raise AssertionError(f"still waiting at {self.now:g} s")

    def send(self, b: int, msg) -> None:
        self.sent.append((self.now, bytes(msg.data)))
        reply = self.answer(bytes(msg.data))
        if reply is not None:
            self.replies[msg.arbitration_id - p.SDO_RX - 1] = reply

    def poll(self, t: float) -> None:
        pass


def upload_reply(index: int, sub: int, data: bytes, n_unused: int) -> bytes:
    """An expedited upload answer: size indicated, ``n_unused`` trailing bytes without data
    (filled with 0xA5 here: CiA 301 leaves them undefined)."""
    cmd = 0x43 | (n_unused << 2)
    return struct.pack("<BHB", cmd, index, sub) + data + b"\xa5" * n_unused


@pytest.mark.parametrize(
    ("data", "n", "signed", "value"),
    [
        (b"\xff", 3, True, -1),  # INTEGER8 −1
        (b"\xff", 3, False, 0xFF),  # UNSIGNED8
        (b"\x00\x80", 2, True, -32768),  # INTEGER16
        (b"\x34\x12\xf0", 1, True, -0x0FEDCC),  # a 3-byte INTEGER24
        (b"\x01\x00\x00\x80", 0, True, -0x7FFFFFFF),  # INTEGER32
    ],
)
def test_an_expedited_upload_takes_only_the_bytes_its_size_bits_say(data, n, signed, value):
    drv = ScriptedDrive(lambda req: upload_reply(0x6072, 0, data, n))
    assert SdoClient(drv).read(0, 0x6072, 0, 1.0, signed=signed) == value


def test_a_lost_request_is_sent_again_every_retry_and_a_silent_drive_times_out():
    """A drive that never answers: the request goes out at once and again every RETRY
    (0.25 s) — 4 times in 1 s, not at every poll — then DriverTimeoutError at the time-out,
    not later, naming the node and the cable."""
    drv = ScriptedDrive(lambda req: None)
    client = SdoClient(drv)
    assert client.RETRY == 0.25
    with pytest.raises(DriverTimeoutError, match=r"no SDO answer from node 2 \(cable index 1\) "
                       r"within 1 s"):  # fmt: skip
        client.read(1, 0x1000, 0, 1.0)
    times = [t for t, _ in drv.sent]
    assert len(times) == 4 and times[0] == 0.0
    assert all(b - a == pytest.approx(0.25, abs=drv.period / 4 + 1e-9)
               for a, b in itertools.pairwise(times))  # fmt: skip
    assert 1.0 < drv.now <= 1.0 + drv.period / 4 + 1e-9


def test_an_answer_lost_twice_comes_on_the_third_request():
    calls = []

    def answer(req: bytes):
        calls.append(req)
        return None if len(calls) < 3 else upload_reply(0x1000, 0, b"\x92\x01\x02\x00", 0)

    drv = ScriptedDrive(answer)
    assert SdoClient(drv).read(0, 0x1000, 0, 2.0, signed=False) == 0x00020192
    assert len(calls) == 3 and drv.now == pytest.approx(0.5, abs=drv.period)


def test_an_abort_names_its_object_and_code():
    abort = struct.pack("<BHBI", 0x80, 0x60FE, 2, 0x06090011)
    drv = ScriptedDrive(lambda req: abort)
    with pytest.raises(SdoAbortError) as exc:
        SdoClient(drv).write(0, 0x60FE, 2, 1, 4, 1.0)
    e = exc.value
    assert (e.node_id, e.index, e.sub, e.code) == (1, 0x60FE, 2, 0x06090011)
    assert "node 1 aborted SDO to 0x60FE:02: code 0x06090011" in str(e)


def test_an_integer_is_read_signed_unless_told_otherwise():
    drv = ScriptedDrive(lambda req: upload_reply(0x6072, 0, b"\xff", 3))
    assert SdoClient(drv).read(0, 0x6072, 0, 1.0) == -1


@pytest.mark.parametrize("filler", [0x00, 0x5A, 0xA5, 0xFF])
@pytest.mark.parametrize("n", [1, 2, 3])
def test_the_unused_bytes_of_an_upload_are_ignored_whatever_they_hold(n, filler):
    """CiA 301 leaves the n unused bytes undefined: their bits decide nothing (a drive that
    fills them with 0x00 and one with 0xFF read the same value)."""
    data = bytes([0x12, 0x34, 0x56][: 4 - n])
    reply = bytes([0x43 | (n << 2), 0x72, 0x60, 0]) + data + bytes([filler]) * n
    drv = ScriptedDrive(lambda req: reply)
    assert SdoClient(drv).read(0, 0x6072, 0, 1.0, signed=False) == int.from_bytes(data, "little")


@pytest.mark.parametrize("cmd", [0x42, 0x46, 0x4A, 0x4E])
def test_an_expedited_upload_without_its_size_indicated_is_four_bytes_whatever_its_n_bits(cmd):
    """Bit 0 (s) clear: the size is not indicated and n is not valid (CiA 301 §7.2.4.3.3): all
    four data bytes are the value."""
    reply = bytes([cmd, 0x72, 0x60, 0, 0x01, 0x02, 0x03, 0x84])
    drv = ScriptedDrive(lambda req: reply)
    assert SdoClient(drv).read(0, 0x6072, 0, 1.0, signed=False) == 0x84030201


@pytest.mark.parametrize("cmd", [0x40, 0x41, 0x45, 0x60, 0x63, 0x23, 0x0B, 0xC2])
def test_an_upload_answered_by_anything_but_an_expedited_upload_is_refused(cmd):
    """A segmented upload's initiate (0x40/0x41/0x45: expedited bit clear), a download's
    confirmation (0x60), other command specifiers with the expedited bit set (0x63, 0x23,
    0x0B, 0xC2): refused in one line naming the node, the answer and the object — never read
    as a value, never as an abort (only 0x80 is one)."""
    reply = bytes([cmd, 0x72, 0x60, 0, 1, 2, 3, 4])
    drv = ScriptedDrive(lambda req: reply)
    with pytest.raises(DriverInitializationError, match=r"node 1: unexpected SDO answer "
                       rf"{cmd:02x}726000.* reading 0x6072:00") as exc:  # fmt: skip
        SdoClient(drv).read(0, 0x6072, 0, 1.0)
    assert not isinstance(exc.value, SdoAbortError)


@pytest.mark.parametrize("cmd", [0x43, 0x4F, 0x61, 0x70, 0xA0, 0xC1])
def test_a_download_answered_by_anything_but_its_confirmation_is_refused(cmd):
    """A download is confirmed by 0x60 alone: an upload's answer (0x43, 0x4F), 0x61, 0x70, a
    block transfer's (0xA0, 0xC1, above the abort's 0x80 but not one) refused, never as an
    abort."""
    reply = bytes([cmd, 0xFE, 0x60, 2, 0, 0, 0, 0])
    drv = ScriptedDrive(lambda req: reply)
    with pytest.raises(DriverInitializationError, match="unexpected SDO answer") as exc:
        SdoClient(drv).write(0, 0x60FE, 2, 1, 4, 1.0)
    assert not isinstance(exc.value, SdoAbortError)


def test_an_answer_to_a_request_sent_at_the_time_out_is_in_time():
    """The time-out is the last instant a request goes out and its answer is taken: a drive
    that answers only from 1 s on (a slow boot), asked with a 1 s time-out on a clock that
    lands on 1 s exactly."""
    drv = ScriptedDrive(lambda req: None)
    drv.period = 1.0  # polls every 0.25 s: exact binary fractions
    drv.answer = lambda req: upload_reply(0x1000, 0, b"\x92\x01\x02\x00", 0) if drv.now >= 1.0 \
        else None  # fmt: skip
    assert SdoClient(drv).read(0, 0x1000, 0, 1.0, signed=False) == 0x00020192
    assert drv.sent[-1][0] == 1.0
