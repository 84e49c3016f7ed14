"""The candump witness of the hardware-in-the-loop demo (tests/tools/test_hil.py): a `candump -L`
log checked against CiA 301/402 from the frames alone, independent of cdprctl's code."""

from __future__ import annotations

import re

import numpy as np
import pytest

# candump -L: "(time) vcan0 ID#DATA", ID 3 hex digits (11-bit) or 8 (29-bit, error frames)
FRAME = re.compile(r"\((\d+\.\d+)\) vcan0 ([0-9A-F]{3}|[0-9A-F]{8})#(R?[0-9A-F]*)")


def check_candump(text: str, nodes: range, rate: float) -> None:
    """The candump log of a fault-free run against CiA 301/402, from the frames alone: each
    node's boot-up message before the master's first NMT command, every node's SDO set-up
    (requests 0x600+n answered on 0x580+n, aborts only "no such object"), NMT
    pre-operational then start, SYNC at the loop's rate, one RPDO per node per SYNC, TPDO1
    answering each SYNC, heartbeats of every drive and of one controller, and no frame of an
    identifier nobody should send — no EMCY (0x80 + node: a drive's fault), no TPDO2 (the
    velocity is derived), no 29-bit, error or remote frame. An SDO request may go unanswered
    twice: the client repeats one lost on a lossy bus, and a repeat may cross its answer."""
    found = FRAME.findall(text)
    odd = [f"{i}#{d}" for _, i, d in found if len(i) == 8 or d.startswith("R")]
    assert not odd, f"29-bit, error or remote frames: {odd[:5]}"  # cdprctl's are 11-bit data
    frames = [(float(t), int(i, 16), bytes.fromhex(d)) for t, i, d in found]
    assert len(frames) > 1000, text[:500]
    ids = {i for _, i, _ in frames}
    expected = {0x000, 0x080} | {base + n for n in nodes for base in (
        0x180, 0x200, 0x580, 0x600, 0x700)}  # fmt: skip
    controller_hb = {i for i in ids if 0x700 < i <= 0x77F and i - 0x700 not in nodes}
    assert len(controller_hb) == 1, sorted(hex(i) for i in controller_hb)
    unexpected = ids - expected - controller_hb  # TPDO2 too: velocity derived, not sent
    assert not unexpected, sorted(hex(i) for i in unexpected)
    nmt = [d for _, i, d in frames if i == 0x000]
    assert nmt[:2] == [bytes([0x80, 0]), bytes([0x01, 0])]  # pre-operational, then start
    first_nmt = next(t for t, i, _ in frames if i == 0x000)
    for n in nodes:  # powered on before the master: its boot-up message first
        first = next(((t, d) for t, i, d in frames if i == 0x700 + n), None)
        assert first is not None, f"node {n}: never heard"
        assert first[1] == b"\x00" and first[0] < first_nmt, f"node {n}: no boot-up first"
    for n in nodes:
        requests = [d for _, i, d in frames if i == 0x600 + n]
        answers = [d for _, i, d in frames if i == 0x580 + n]
        assert requests and len(answers) >= len(requests) - 2  # a retry may cross its answer
        aborts = [d for d in answers if d[0] == 0x80]
        assert all(int.from_bytes(d[4:8], "little") == 0x06020000 for d in aborts)
        assert any(i == 0x700 + n for _, i, _ in frames), f"no heartbeat of node {n}"
    syncs = [t for t, i, _ in frames if i == 0x080]
    cyclic = np.diff(syncs[len(syncs) // 4:])  # the loop's, past the set-up
    assert np.median(cyclic) == pytest.approx(1.0 / rate, rel=0.15)
    # over the loop's second half: a TPDO1 from every node for each SYNC, and at least one RPDO
    # before each (a late cycle's targets may go out twice: driver.py, resent_targets)
    last = max(t for t, _, _ in frames)
    window = [i for t, i, _ in frames if syncs[len(syncs) // 2] <= t < last - 1.0]
    n_syncs = window.count(0x080)
    assert n_syncs > 50
    for n in nodes:
        assert abs(window.count(0x180 + n) - n_syncs) <= 2, n
        assert window.count(0x200 + n) >= n_syncs - 2, n
