"""CAN bus-load budget per bus, from the frames of one control cycle.

Classic CAN 2.0A frame with ``n`` data bytes, worst-case bit stuffing (Davis, Burns, Bril,
Lukkien 2007, "Controller Area Network (CAN) schedulability analysis", eq. (1)):
``bits = 8n + 47 + floor((34 + 8n − 1)/4)`` (the last term: stuff bits), so SYNC with its counter
(1 byte) is 65 bits, a 4-byte PDO 95, an 8-byte PDO 135 (DESIGN.md, with an empty SYNC of 55: 8
CiA 402 drives → 1,895 bits per cycle; 1,905 with the counter).
"""

from __future__ import annotations

from dataclasses import dataclass

from cdprctl.model.drives import DrivesConfig
from cdprctl.model.sensors import DATA_SIZES, LoadCell

WARN_LOAD = 0.70
MAX_LOAD = 1.00


def frame_bits(n_bytes: int) -> int:
    """Worst-case bits on the wire of a standard-id frame with ``n_bytes`` of data."""
    return 8 * n_bytes + 47 + (34 + 8 * n_bytes - 1) // 4


@dataclass(frozen=True)
class BusLoad:
    bus: int
    interface: str
    channel: str
    bitrate: int
    drives: int
    bits_per_cycle: int
    rate: float  # Hz
    load: float  # fraction of the bitrate
    frames: str  # what a cycle holds

    @property
    def verdict(self) -> str:
        if self.load > MAX_LOAD:
            return "REFUSED (> 100 %)"
        if self.load > WARN_LOAD:
            return "WARNING (> 70 %)"
        return "ok"


def cycle_frames(
    driver: str, n: int, velocity_pdo: bool, n_position: int = 0
) -> list[tuple[str, int, int]]:
    """(what, count, data bytes) of one control cycle on a bus with ``n`` drives, of which
    ``n_position`` in position mode."""
    if driver == "odrive":
        # Set_Input_Pos (8: target, velocity and torque feed-forward) after an RTR for
        # Get_Torques (0), or Set_Input_Torque (4) out; Get_Encoder_Estimates (8) and
        # Get_Torques (8) in
        frames: list[tuple[str, int, int]] = []
        if n_position:
            frames += [("Get_Torques RTR", n_position, 0), ("Set_Input_Pos", n_position, 8)]
        if n - n_position:
            frames.append(("Set_Input_Torque", n - n_position, 4))
        frames.append(("Encoder_Estimates", n, 8))
        if n_position:
            frames.append(("Get_Torques answering the RTR", n_position, 8))
        if n - n_position:
            frames.append(("Get_Torques (cyclic)", n - n_position, 8))
        return frames
    frames = [("SYNC with its counter", 1, 1)]
    if n_position:
        frames.append(("RPDO1 controlword+position+torque offset", n_position, 8))
    if n - n_position:
        frames.append(("RPDO1 controlword+torque", n - n_position, 4))
    frames.append(("TPDO1 status+torque+position", n, 8))
    if velocity_pdo:
        frames.append(("TPDO2 velocity", n, 4))
    return frames


def bus_loads(drives: DrivesConfig, rate: float, heartbeat_rate: float = 10.0,
              cells: tuple[LoadCell, ...] = ()) -> list[BusLoad]:  # fmt: skip
    """The load of each bus at the control ``rate`` (Hz), heartbeats (1 byte, every drive and
    the controller, ``heartbeat_rate`` Hz) included, and the TPDO of each load cell on it
    (``cells``: ``[[sensors.load_cells]]``, its value alone as the set-up maps it)."""
    out = []
    for b, bus in enumerate(drives.buses):
        n = len(bus.cables)
        n_position = sum(drives.mode_of(c) == "csp" for c in bus.cables)
        frames = cycle_frames(drives.driver, n, drives.velocity_source == "pdo", n_position)
        for size in sorted({DATA_SIZES[c.data_type] for c in cells if c.bus == b}):
            count = sum(c.bus == b and DATA_SIZES[c.data_type] == size for c in cells)
            frames.append(("load cell TPDO", count, size))
        bits = sum(count * frame_bits(nb) for _, count, nb in frames)
        hb_bits_per_s = (n + 1) * frame_bits(1 if drives.driver == "cia402" else 8) * heartbeat_rate
        load = (bits * rate + hb_bits_per_s) / bus.bitrate
        desc = ", ".join(f"{c} x {what} ({nb} B)" for what, c, nb in frames)
        out.append(BusLoad(b, bus.interface, bus.channel, bus.bitrate, n, bits, rate, load, desc))
    return out


def check_bus_load(drives: DrivesConfig, rate: float,
                   cells: tuple[LoadCell, ...] = ()) -> tuple[list[str], list[str]]:  # fmt: skip
    """(warnings, errors): a bus above 70 % warns, above 100 % refuses to start."""
    warnings, errors = [], []
    for bl in bus_loads(drives, rate, cells=cells):
        msg = (
            f"CAN bus {bl.bus} ({bl.interface} {bl.channel}, {bl.bitrate} bit/s): "
            f"{bl.load * 100:.1f} % load at {rate:g} Hz ({bl.bits_per_cycle} bits per cycle, "
            f"{bl.drives} drives)"
        )
        if bl.load > MAX_LOAD:
            errors.append(
                msg + ": more than the bus can carry; lower the rate, split the "
                "drives over more buses or raise the bitrate"
            )
        elif bl.load > WARN_LOAD:
            spare = "retries and SDO traffic" if drives.driver == "cia402" else "retries"
            warnings.append(msg + f": above 70 %, little room for {spare}")
    return warnings, errors
