"""The ``[drives]`` section of a robot description: which driver, which CAN buses, which node
drives which cable, and the drive-side timing and scaling.

Absent, every robot gets one simulated bus: CiA 402 drives with node ids 1..m on python-can's
``virtual`` interface, channel ``cdpr-<name>``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from cdprctl.model.buses import BusConfig, default_buses, read_buses
from cdprctl.model.reader import Choice, Flag, Number, TableReader, Text, read_fields

DRIVES_KEYS = (
    "driver",
    "mode",
    "position_loop_bandwidth",
    "following_error_window",
    "following_error_timeout",
    "target_extrapolation",
    "brake_release_time",
    "rated_torque",
    "torque_constant",
    "feedback_timeout",
    "missed_feedback_limit",
    "heartbeat_timeout",
    "heartbeat_period",
    "controller_node_id",
    "comm_timeout",
    "velocity_source",
    "pdo_mapping",
    "encoders",
    "assume_home_at_start",
    "log_file",
    "buses",
)
DRIVERS = ("cia402", "odrive")


@dataclass(frozen=True)
class DrivesConfig:
    driver: str = "cia402"
    # "cst": the controller sends torques (cyclic synchronous torque); "csp": it sends each
    # winch's position target with the torque as feed-forward (cyclic synchronous position,
    # torque offset): the fast loop per cable is the drive's own (docs/control.md)
    mode: str = "cst"
    # Hz: the simulated drives' position loop in "csp" (kp = J ω², kd = 2 ζ J ω on the rotor
    # inertia, ζ = 0.7); a real drive is tuned with its vendor's tool and ignores this
    position_loop_bandwidth: float = 50.0
    # position mode, drive-side supervision (CiA 402 0x6065, 0x6066): m of cable a winch may
    # stay off its target, and for how long (s), before its drive faults (EMCY 0x8611) and
    # brakes. None: the error at which the position loop alone asks for the full torque
    # (``following_error_window_rad``), which only a load beyond the winch or an encoder that
    # jumped reaches. 3 ms: rowc's drives bring a 0.5 rad encoder jump back under that window
    # in 5-8 ms, moving the platform 8 mm; caught after 3 ms it moves 0.1 mm. 2 ms also
    # stopped 1 of 3 runs at 5 % frame loss (a stale RPDO's catch-up; lock-step)
    following_error_window: float | None = None
    following_error_timeout: float = 0.003
    # position mode: s a drive goes on at its target's last rate when the next target is late
    # (a SYNC or an RPDO late or lost) before it holds the target — vendor-specific; the
    # simulated drives do what this says. The reference waits out the rest of a longer stall
    # of the loop: moving on by all of it, the next target stepped ahead of the held drives
    # (78 ms at 0.2 m/s on rowc: 0.6 rad, a following-error fault)
    target_extrapolation: float = 0.05
    # position mode: s after the drives report enabled before their torque is taken as the
    # cables' tensions (the tension supervision, the force feedback, the disturbance
    # estimate): a brake still opening holds part of the load, and the first samples a drive
    # sends once enabled are the torque before it applied any. Across processes on a loaded
    # machine (two CPU hogs) the read that found the drives enabled and the two after it gave
    # zero torque: up to 79 N of internal tension error, past the limit in 4 runs of 20, and
    # the tests' CI stopped on it 20 ms after enabling. Set it to the brakes' opening time
    # from their datasheet, if longer
    brake_release_time: float = 0.05
    rated_torque: float = 1.0  # N·m that 1000 per-mille stand for (CiA 402 0x6076)
    # N·m/A of the motors (ODrive: 8.27 / KV): an ODrive axis in position mode gets its
    # current limit, torque_limit / torque_constant, by CAN (Set_Limits); None: not given
    torque_constant: float | None = None
    # s of running cycles without feedback from a drive before it is taken as lost: a time,
    # not a count of cycles, so the tolerance is the same at every rate (30 ms; the old count
    # of 5 missed reads was 10-12 ms at 500 Hz, 20 ms at 250 Hz). A stall of the loop itself
    # counts at most two periods: no SYNC went out, the drives could not answer
    # (drivers/liveness.py)
    feedback_timeout: float = 0.03
    heartbeat_timeout: float = 0.5  # s without a drive's heartbeat: drive lost
    heartbeat_period: float = 0.1  # s, the controller's own heartbeat
    controller_node_id: int = 127
    comm_timeout: float = 0.1  # s without RPDO/SYNC: the drive quick-stops (drive side)
    velocity_source: str = "derived"  # "derived" from positions, or "pdo" (TPDO2, 0x606C)
    # "configure": the driver writes the PDO mapping it needs by SDO at every start (CiA 402
    # drives); "static": it only reads it, and refuses a drive whose mapping differs
    pdo_mapping: str = "configure"
    # "incremental": a drive's position counter restarts at power-up (or a reset node), so a
    # calibration record holds only until a drive is reset; "absolute": multi-turn encoders
    # keep their count, the record holds until the robot's geometry changes (docs/homing.md)
    encoders: str = "incremental"
    # True: the encoders read zero where each cable's unstretched length is its length at the
    # home pose, with no calibration record (the simulated robot started at home; a real robot
    # only on a fixture that guarantees it): `cdprctl run` trusts it (docs/homing.md)
    assume_home_at_start: bool = False
    log_file: str | None = None  # python-can logger file (.log, .asc, .blf, .csv)
    buses: tuple[BusConfig, ...] = ()
    # cable indices whose drives stay in torque mode in position mode: the grippers' cables
    # (set from [[grippers]] by the loader), whose tensions squeeze the jaws
    torque_cables: tuple[int, ...] = ()

    @property
    def holds_lengths(self) -> bool:
        """True in position mode: the drives' own loops hold the cables' lengths (all but
        ``torque_cables``)."""
        return self.mode == "csp"

    def mode_of(self, cable: int) -> str:
        """The mode of cable index ``cable``'s drive: ``mode``, but torque mode (``cst``) for
        the ``torque_cables``."""
        return "cst" if self.mode == "cst" or cable in self.torque_cables else "csp"

    def position_gains(
        self, rotor_inertia: float, bandwidth: float | None = None
    ) -> tuple[float, float]:
        """(kp N·m/rad, kd N·m·s/rad) of a drive's position loop: the rotor alone placed at
        ``bandwidth`` (Hz; default ``position_loop_bandwidth``) with damping
        ``POSITION_LOOP_DAMPING`` (kp = J ω², kd = 2 ζ J ω); the cable adds its stiffness on
        top (sim_backend servo.servo_torque)."""
        w = 2.0 * math.pi * (self.position_loop_bandwidth if bandwidth is None else bandwidth)
        return rotor_inertia * w * w, 2.0 * POSITION_LOOP_DAMPING * rotor_inertia * w

    def following_error_window_rad(self, winch: Any, kp: float | None = None) -> float:
        """rad at the motor: ``following_error_window`` (m of cable) through the drum, or by
        default the error at which the position loop alone asks for the winch's full torque
        (``torque_limit / kp``, kp N·m/rad by default ``position_gains``'; rowc: 0.18 rad,
        1.6 mm of cable)."""
        if self.following_error_window is not None:
            return self.following_error_window * winch.gear_ratio / winch.drum_radius
        stiffness = self.position_gains(winch.rotor_inertia)[0] if kp is None else kp
        return winch.torque_limit / stiffness

    def node_of(self, cable: int) -> tuple[int, int]:
        """(bus index, node id) of a cable."""
        for b, bus in enumerate(self.buses):
            if cable in bus.cables:
                return b, bus.node_ids[bus.cables.index(cable)]
        raise KeyError(cable)


MODES = ("cst", "csp")
ENCODERS = ("incremental", "absolute")
POSITION_LOOP_DAMPING = 0.7  # of the simulated drives' position loop


# ``[drives] mode`` where the file does not say: position mode, whose gains all come from the
# robot's model (docs/control.md, "Gains from the model"); both drivers have it (ODrive:
# Set_Input_Pos, its cascaded loops' gains set by CAN)
DEFAULT_MODE = "csp"
ODRIVE_MAX_TORQUE_FF = 32.767  # N·m: Set_Input_Pos's int16 torque feed-forward × 0.001
# A: the current limits an ODrive takes for a winch's torque limit: below 1 A no winch holds a
# cable (a KV typed as the torque constant gives 0.03 A); 120 A is the ODrive Pro's peak
ODRIVE_CURRENT_RANGE = (1.0, 120.0)


def default_drives(name: str, n_cables: int, rated_torque: float) -> DrivesConfig:
    """One bus of all the drives, node ids 1..m, in ``DEFAULT_MODE``."""
    return DrivesConfig(
        mode=DEFAULT_MODE, rated_torque=rated_torque, buses=default_buses(name, n_cables)
    )


#: the plain keys of ``[drives]``, in the order they are read: what decides the others
#: first (``_odrive_limits`` relates them), then the timing and scaling, then the set-up's
DRIVES_FIRST = (
    Choice("driver", DRIVERS, lenient=True),
    Choice("mode", MODES, lenient=True),
    Number("torque_constant", "N·m/A", positive=True),
)
DRIVES_TIMING = (
    Number("position_loop_bandwidth", "Hz", positive=True),
    Number("following_error_window", "m", positive=True),
    Number("following_error_timeout", "s", positive=True, maximum=65.535),
    Number("target_extrapolation", "s", positive=True),
    Number("brake_release_time", "s", minimum=0.0, maximum=1.0),
    Number("rated_torque", "N·m", positive=True),
    Number("feedback_timeout", "s", positive=True),
)
DRIVES_SETUP = (
    # a CiA 402 drive beats five times a timeout (drivers/cia402/drive_setup.py) and 0x1017
    # is whole ms in 16 bits: 2 ms to 65.535 s between beats
    Number("heartbeat_timeout", "s", minimum=0.01, maximum=327.675),
    Number("heartbeat_period", "s", positive=True),
    Number("controller_node_id", "", minimum=1, maximum=127, integer=True),
    Number("comm_timeout", "s", positive=True),
    Choice("velocity_source", ("derived", "pdo"), rule="must be 'derived' or 'pdo'"),
    Choice("pdo_mapping", ("configure", "static"),
           rule="must be 'configure' (the driver writes the PDO mapping by SDO) or 'static' "
           "(it only checks it)"),
    Choice("encoders", ENCODERS,
           rule="must be 'incremental' (the counter restarts at power-up) or 'absolute' "
           "(multi-turn, kept across power-ups)"),
    Flag("assume_home_at_start"),
    Text("log_file"),
)  # fmt: skip


def read_drives(
    rd: TableReader,
    data: dict[str, Any],
    cable_names: list[str],
    name: str,
    rated_default: float,
    max_torque_limit: float = 0.0,
) -> DrivesConfig | None:
    """``max_torque_limit`` (N·m): the largest of the winches' ``torque_limit``."""
    n0 = len(rd.errors)
    t = rd.section(data, "drives", DRIVES_KEYS)
    if t is None:
        return default_drives(name, len(cable_names), rated_default)
    defaults = DrivesConfig(mode=DEFAULT_MODE, rated_torque=rated_default)
    vals: dict[str, Any] = {}
    read_fields(rd, t, "drives", DRIVES_FIRST, defaults, vals)
    _odrive_limits(rd, t, vals, max_torque_limit)
    read_fields(rd, t, "drives", DRIVES_TIMING, defaults, vals)
    if "missed_feedback_limit" in t:
        rd.error(
            "drives.missed_feedback_limit",
            t["missed_feedback_limit"],
            "cycles",
            "is replaced by feedback_timeout, a time in s (e.g. feedback_timeout = 0.03): a "
            "count of cycles meant a different time at every rate",
        )
    read_fields(rd, t, "drives", DRIVES_SETUP, defaults, vals)
    buses = read_buses(rd, t, cable_names, name, vals.get("controller_node_id"), vals["driver"])
    if len(rd.errors) > n0:
        return None
    vals["rated_torque"] = float(vals["rated_torque"])
    return DrivesConfig(**vals, buses=tuple(buses))


def _odrive_limits(
    rd: TableReader, t: dict[str, Any], vals: dict[str, Any], max_torque_limit: float
) -> None:
    """What an ODrive asks of the other keys: its torque constant in position mode (its
    current limit goes by CAN), a current limit it can drive, and a torque feed-forward its
    int16 carries."""
    driver, mode = vals["driver"], vals["mode"]
    torque_constant = vals.get("torque_constant")
    if mode == "csp" and driver == "odrive" and "torque_constant" not in t:
        rd.error_missing(
            "drives.torque_constant", "N·m/A",
            "with an ODrive in position mode (mode = 'csp', the default), which gets its "
            "current limit torque_limit / torque_constant by CAN: the motors' torque constant "
            "(8.27 / KV), or mode = 'cst' for torque mode",
        )  # fmt: skip
    if torque_constant is not None and driver == "odrive" and max_torque_limit > 0.0:
        current = max_torque_limit / float(torque_constant)  # A, Set_Limits' current limit
        if not ODRIVE_CURRENT_RANGE[0] <= current <= ODRIVE_CURRENT_RANGE[1]:
            rd.error(
                "drives.torque_constant", torque_constant, "N·m/A",
                f"gives a current limit of {current:.3g} A for the winches' {max_torque_limit:g} "
                f"N·m (torque_limit / torque_constant), outside [{ODRIVE_CURRENT_RANGE[0]:g}, "
                f"{ODRIVE_CURRENT_RANGE[1]:g}] A, what an ODrive drives (Kt = 8.27 / KV: a KV "
                "typed for it gives far below)",
            )  # fmt: skip
    if mode == "csp" and driver == "odrive" and max_torque_limit > ODRIVE_MAX_TORQUE_FF:
        rd.error(
            "winch.torque_limit", max_torque_limit, "N·m",
            f"must be <= {ODRIVE_MAX_TORQUE_FF} with ODrive axes in position mode: "
            "Set_Input_Pos carries the torque feed-forward as int16 × 0.001 N·m",
        )  # fmt: skip
