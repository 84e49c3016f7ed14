"""The CiA 402 driver's cyclic decode and encode, compiled.

Per frame, Python does only what it must (``recv``, the dispatch lookup, ``struct.unpack``);
the per-cable work of a cycle (32-bit unwrap, plausibility, statusword decode, derived velocity,
controlword choice, per-mille conversion) runs here, once per cycle. Done per cable in Python it
cost ~60 µs of a 500 Hz cycle on 8 drives (benchmarks/bench_loop.py).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cdprctl.core.numerics import clamp, cycle_kernel, plausible_step
from drivers.cia402 import protocol as p
from drivers.cia402.sync_clock import sync_instant
from drivers.vocabulary import DriveState

# each CiA 402 power state as the control side's protocol-independent drive state
GENERIC_STATE = {
    p.PowerState.NOT_READY_TO_SWITCH_ON: DriveState.DISABLED,
    p.PowerState.SWITCH_ON_DISABLED: DriveState.DISABLED,
    p.PowerState.READY_TO_SWITCH_ON: DriveState.READY,
    p.PowerState.SWITCHED_ON: DriveState.READY,
    p.PowerState.OPERATION_ENABLED: DriveState.ENABLED,
    p.PowerState.QUICK_STOP_ACTIVE: DriveState.QUICK_STOP,
    p.PowerState.FAULT_REACTION_ACTIVE: DriveState.FAULT,
    p.PowerState.FAULT: DriveState.FAULT,
}

#: PowerState of every statusword, by its bits 0-6 (the only ones Table 30 looks at)
POWER_STATE_OF_SW7 = np.array([int(p.decode_statusword(sw)) for sw in range(128)], dtype=np.int64)
#: controlword that moves each PowerState towards ENABLED
CONTROLWORD_TOWARDS_ENABLED = np.array(
    [int(p.TOWARDS_ENABLED[s]) for s in sorted(p.PowerState)], dtype=np.int64
)
_FAULT = int(p.PowerState.FAULT)
_FAULT_REACTION = int(p.PowerState.FAULT_REACTION_ACTIVE)
_FAULT_RESET = int(p.Command.FAULT_RESET)
_DISABLE_VOLTAGE = int(p.Command.DISABLE_VOLTAGE)


class Decoded(NamedTuple):
    """The driver's decoding state per cable (arrays, written in place; the kernels take it
    as ``kernel_args``): ``raw[c]`` = (last 32-bit position, 1 if any, implausible frames in a
    row), ``counts`` the unwrapped multi-turn counts, ``ps`` the power state, ``emcy`` the last
    EMCY code (0: none), ``prev[c]`` = (last position rad, its instant s)."""

    raw: np.ndarray
    counts: np.ndarray
    ps: np.ndarray
    emcy: np.ndarray
    prev: np.ndarray


@cycle_kernel
def tpdo1_frame(
    c, sw, pm, pos, stamp, period, max_speed, rad_per_count, rated_torque, ps_table, decoded,
    torque, fresh, fb_stamp, rate,
):  # pragma: no cover - compiled  # fmt: skip
    """Apply one TPDO1 of cable ``c`` (statusword, torque per-mille, 32-bit position) sampled
    at ``stamp`` s; 1 when it is dropped, else 0. A position step no motor (``max_speed``
    rad/s) can make within the time since the last accepted sample (plus a ``period`` of
    slack) is a corrupted frame: dropped whole. Sets the power state, torque actual (N·m,
    ``rated_torque`` per 1000 per-mille), unwrapped counts, freshness, sample instant (s)
    and ``rate`` (counts/s: the last step over its time, for ``sync_instant``)."""
    raw, counts, ps = decoded[0], decoded[1], decoded[2]
    have = raw[c, 1] != 0
    step = 0
    if have:
        step = ((pos - raw[c, 0] + 0x80000000) & 0xFFFFFFFF) - 0x80000000
        prev = fb_stamp[c]
        if np.isfinite(prev):
            if plausible_step(step * rad_per_count[c], max_speed[c], stamp - prev, period):
                raw[c, 2] = 0
                if stamp > prev:
                    rate[c] = step / (stamp - prev)
            else:
                raw[c, 2] += 1
                return 1
    ps[c] = ps_table[sw & 0x7F]
    torque[c] = pm * rated_torque / 1000.0
    if have:
        counts[c] += step
    else:
        counts[c] = pos
    raw[c, 0] = pos
    raw[c, 1] = 1
    fresh[c] = True
    fb_stamp[c] = stamp
    return 0


@cycle_kernel
def tpdo1_synced_kernel(
    n, frames, syncs, seqs, answered, lag_max, fallback, period, max_speed, rad_per_count,
    rated_torque, ps_table, decoded, torque, fresh, fb_stamp, rate,
):  # pragma: no cover - compiled  # fmt: skip
    """Apply ``n`` TPDO1 frames in their order of arrival (``tpdo1_frame``), ``frames[i]`` =
    (cable, statusword, torque per-mille, 32-bit position), each stamped at the instant of
    the SYNC it answers (``sync_clock.sync_instant``); ``decoded``: the :class:`Decoded`
    state; ``seqs[0]`` the newest SYNC's sequence number. Returns the number of frames
    dropped."""
    raw = decoded[0]
    seq = seqs[0]
    dropped = 0
    for i in range(n):
        c, pos = frames[i, 0], frames[i, 3]
        stamp = sync_instant(c, pos, syncs, seq, answered, lag_max, raw, fb_stamp, rate,
                             fallback)  # fmt: skip
        dropped += tpdo1_frame(
            c, frames[i, 1], frames[i, 2], pos, stamp, period, max_speed, rad_per_count,
            rated_torque, ps_table, decoded, torque, fresh, fb_stamp, rate,
        )  # fmt: skip
    return dropped


@cycle_kernel
def decode_tpdo1_kernel(n, raw, cables, frames):  # pragma: no cover - compiled
    """``frames[i]`` ← (cable, statusword, torque per-mille, 32-bit position) of the first
    ``n`` TPDO1s: ``cables[i]`` and the 8 bytes ``raw[i]`` as ``protocol.TPDO1_STRUCT``
    (<Hhi, little-endian, two's complement) unpacks them."""
    for i in range(n):
        b = raw[i]
        frames[i, 0] = cables[i]
        frames[i, 1] = np.int64(b[0]) | np.int64(b[1]) << 8
        torque = np.int64(b[2]) | np.int64(b[3]) << 8
        frames[i, 2] = torque - 0x10000 if torque >= 0x8000 else torque
        pos = np.int64(b[4]) | np.int64(b[5]) << 8 | np.int64(b[6]) << 16 | np.int64(b[7]) << 24
        frames[i, 3] = pos - 0x100000000 if pos >= 0x80000000 else pos


@cycle_kernel
def state_kernel(
    fresh, fb_stamp, rad_per_count, derived, generic, decoded, feedback
):  # pragma: no cover - compiled
    """Motor position (rad) of the fresh cables, their velocity (rad/s) by differences of
    sample instants (``fb_stamp``, s) when ``derived``, the generic state (``generic``: of
    each power state) and fault code of every cable, from the :class:`Decoded` state into
    ``feedback`` = (position, velocity, state, fault_code) of ``WinchStates``. True if a drive
    is in fault."""
    counts, ps, emcy, prev = decoded[1], decoded[2], decoded[3], decoded[4]
    position, velocity, state, fault_code = feedback
    fault = False
    for c in range(len(fresh)):
        if fresh[c]:
            pos = counts[c] * rad_per_count[c]
            stamp = fb_stamp[c]
            if derived and np.isfinite(prev[c, 1]):
                dt = stamp - prev[c, 1]
                if dt > 0.0:
                    velocity[c] = (pos - prev[c, 0]) / dt
            prev[c, 0] = pos
            prev[c, 1] = stamp
            position[c] = pos
        state[c] = generic[ps[c]]
        fault_code[c] = emcy[c]
        if emcy[c] != 0 or ps[c] == _FAULT:
            fault = True
    return fault


@cycle_kernel
def controlword_kernel(
    torques, ps, emcy, reset, enable, rated_torque, towards, out
):  # pragma: no cover - compiled
    """``out[c]`` = (controlword, target torque per-mille) of each drive's RPDO1: a fault
    reset edge (``reset`` cycles left: 0x00 then 0x80) to drives in fault, else towards
    enabled or disable voltage; torques (N·m) rounded half to even like Python's ``round``,
    within ±32767 per-mille."""
    for c in range(len(torques)):
        s = ps[c]
        if reset > 0 and (s == _FAULT or s == _FAULT_REACTION):  # noqa: SIM109 - compiled
            if reset <= 2:
                out[c, 0] = _FAULT_RESET
                emcy[c] = 0
            else:
                out[c, 0] = _DISABLE_VOLTAGE
        elif enable:
            out[c, 0] = towards[s]
        else:
            out[c, 0] = _DISABLE_VOLTAGE
        pm = np.rint(torques[c] * 1000.0 / rated_torque)
        out[c, 1] = int(clamp(pm, -32767.0, 32767.0))


@cycle_kernel
def target_rates_kernel(targets, t, last, last_t, max_speed, rate):  # pragma: no cover - compiled
    """``rate`` (rad/s) ← each position target's rate since the last cycle's (``last`` at
    ``last_t``; within ``max_speed``, rad/s; 0 without a last cycle). ``last`` ← ``targets``."""
    gap = t - last_t
    for c in range(len(targets)):
        r = 0.0
        if 0.0 < gap < 1.0:
            r = (targets[c] - last[c]) / gap
            r = min(max(r, -max_speed[c]), max_speed[c])
        rate[c] = r
        last[c] = targets[c]


@cycle_kernel
def carry_targets_kernel(targets, rate, late, out):  # pragma: no cover - compiled
    """``out`` (rad) ← each position target carried ``late`` s on at its ``rate``: the target
    for the instant its SYNC leaves, not the instant the cycle started."""
    for c in range(len(targets)):
        out[c] = targets[c] + rate[c] * late


@cycle_kernel
def target_counts_kernel(targets, rad_per_count, out):  # pragma: no cover - compiled
    """``out[c]`` ← the position target (rad) of each drive in encoder counts, as the 32-bit
    signed value of 0x607A (the drive unwraps it against its own position actual)."""
    for c in range(len(targets)):
        n = np.int64(np.rint(targets[c] / rad_per_count[c]))
        out[c] = ((n + 0x80000000) & 0xFFFFFFFF) - 0x80000000


@cycle_kernel
def pack_rpdo1_kernel(fields, counts, position, data):  # pragma: no cover - compiled
    """``data[c]`` (the bytes of drive ``c``'s RPDO1) ← its controlword and, in position mode
    (``position[c]``), its target ``counts`` and torque offset, else its target torque:
    ``protocol.RPDO1_CSP_STRUCT`` (<Hih) and ``RPDO1_STRUCT`` (<Hh), little-endian, two's
    complement. Packed here, no Python int is built per value (the values are within their
    fields: ``controlword_kernel``, ``target_counts_kernel``)."""
    for c in range(fields.shape[0]):
        d = data[c]
        cw, pm = fields[c, 0], fields[c, 1]
        d[0], d[1] = cw & 0xFF, (cw >> 8) & 0xFF
        k = 2
        if position[c]:
            n = counts[c]
            for b in range(4):
                d[k + b] = (n >> (8 * b)) & 0xFF
            k = 6
        d[k], d[k + 1] = pm & 0xFF, (pm >> 8) & 0xFF
