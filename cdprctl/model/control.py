"""The ``[control]`` section of a robot description: loop rate, gains, trajectory limits, TDA,
safety limits and real-time settings. Every key has a default; the section may be absent."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cdprctl.model.reader import (
    Choice,
    Field,
    Flag,
    Number,
    TableReader,
    Vector,
    positive,
    read_fields,
    read_section,
)

CONTROL_KEYS = (
    "rate",
    "bandwidth",
    "axis_bandwidth",
    "damping_ratio",
    "velocity_filter",
    "observer_bandwidth",
    "disturbance_bandwidth",
    "force_feedback",
    "max_velocity",
    "max_acceleration",
    "max_jerk",
    "max_angular_velocity",
    "max_angular_acceleration",
    "max_angular_jerk",
    "jog_deadman",
    "tda",
    "safety",
    "realtime",
    "friction_compensation",
    "external_wrench",
)
TDA_KEYS = ("method", "nu", "direction", "max_tension_rate", "impose")
SAFETY_KEYS = (
    "max_position_error",
    "max_angle_error",
    "max_speed",
    "max_feedback_age",
    "stop_duration",
    "max_saturation_time",
    "tension_margin",
    "max_fk_residual",
    "max_tension_disagreement",
)
REALTIME_KEYS = (
    "sleep_margin", "sched_priority", "cpu", "lock_memory", "freeze_gc", "cpu_wakeup_latency",
)
METHODS = ("pinv", "closed-form", "barycenter", "min-2-norm", "min-1-norm", "sotda", "energy", "qp")


@dataclass(frozen=True)
class ImposeConfig:
    cable: int  # 0-based
    quantity: str  # energy | tension | deformation
    value: float


@dataclass(frozen=True)
class ControlConfig:
    rate: float = 500.0  # Hz
    bandwidth: float = 1.0  # Hz, closed-loop natural frequency of the PD pose loop
    # Hz per axis (x, y, z, roll, pitch, yaw), replacing ``bandwidth`` where given: a badly
    # conditioned direction needs a slower loop (docs/control.md, "Per-axis bandwidth").
    axis_bandwidth: tuple[float, ...] | None = None
    damping_ratio: float = 1.0
    # Hz, first-order low-pass on the finite-difference twist (docs/control.md: rate and filter)
    velocity_filter: float = 40.0
    # Hz, the external-wrench observer's bandwidth (control/cycle/observer.py); 0: off
    observer_bandwidth: float = 0.0
    # Hz, position mode: the external wrench estimated from the measured tensions, fed
    # forward to the TDA (control/cycle/cable_space.py); 0: off; None (default): from the model,
    # the platform's lowest mode over 6 (cable_space.disturbance_bandwidth says why)
    disturbance_bandwidth: float | None = None
    # position mode: the integral force feedback's gain and leak, as a multiple of the
    # platform's lowest mode on its cables (stiffness.lowest_mode; rowc 19.9 rad/s); 0: off
    force_feedback: float = 1.0
    max_velocity: float = 0.3  # m/s
    max_acceleration: float = 1.0  # m/s²
    max_jerk: float = 10.0  # m/s³
    max_angular_velocity: float = 0.3  # rad/s
    max_angular_acceleration: float = 1.0  # rad/s²
    max_angular_jerk: float = 10.0  # rad/s³
    jog_deadman: float = 0.2  # s without a jog command before the jog stops (control/intake/jog.py)
    friction_compensation: bool = True  # winch viscous + Coulomb friction feedforward
    external_wrench: tuple[float, ...] = (0.0,) * 6  # N, N·m at P, base frame: known, fed forward
    tda_method: str = "barycenter"
    tda_nu: float = 0.0
    tda_direction: tuple[float, float, float] = (0.0, 1.0, 0.0)
    max_tension_rate: float = 5000.0  # N/s per cable
    impositions: tuple[ImposeConfig, ...] = ()
    max_position_error: float = 0.05  # m, tracking error that faults
    max_angle_error: float = 0.1  # rad
    max_speed: float = 1.0  # m/s, estimated platform speed that faults
    max_feedback_age: float = 0.05  # s
    stop_duration: float = 0.5  # s, controlled stop before the brakes close
    # s: how long the cables may give only part of the PID's feedback wrench (the commanded
    # wrench saturated into the feasible set, docs/control.md) before the supervisor faults
    max_saturation_time: float = 1.0
    tension_margin: float = 0.0  # N, kept from each limit by the TDA
    # m RMS: cable lengths no pose explains (an encoder fault). Soft cables stretch under forces
    # the controller does not know (Sensors 2019 springs: 30 N ≈ 10 mm), so they need more.
    max_fk_residual: float = 0.005
    # of each cable's tension range (t_max − t_min): in position mode, the measured tensions'
    # internal part (what no external wrench explains) beyond this is a cable whose length is
    # not what its encoder says (control/cycle/cable_space.py). rowc: ≤ 3.3 N under a 50 N jet,
    # 48-110 N after an encoder jump, a slip or a snapped cable (lock-step, measured)
    max_tension_disagreement: float = 0.1
    sleep_margin: float = 0.0002  # s, spin (instead of sleep) this long before each deadline
    sched_priority: int = 80  # SCHED_FIFO priority when permitted
    cpu: int = -1  # CPU to pin the loop to; -1: the last one
    lock_memory: bool = True
    freeze_gc: bool = True
    # s: the idle CPUs' longest wake-up while the loop runs (the kernel's PM QoS request, as
    # cyclictest makes it; core/cpu_idle.py); negative: the machine's idle states left alone
    cpu_wakeup_latency: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def period(self) -> float:
        return 1.0 / self.rate


#: the plain keys of ``[control]`` and its tables, in the order they are read
CONTROL_FIELDS: tuple[Field, ...] = (
    Number("rate", "Hz", positive=True, maximum=10000.0),
    Number("bandwidth", "Hz", positive=True),
    Vector("axis_bandwidth", "Hz", length=6, positive=True),
    Number("damping_ratio", "", positive=True),
    Number("velocity_filter", "Hz", positive=True),
    Number("observer_bandwidth", "Hz", minimum=0.0),
    Number("disturbance_bandwidth", "Hz", minimum=0.0, maximum=5.0),
    Number("force_feedback", "× the lowest mode", minimum=0.0, maximum=10.0),
    Number("jog_deadman", "s", positive=True, maximum=5.0),
    *positive(("max_velocity", "m/s"), ("max_acceleration", "m/s²"), ("max_jerk", "m/s³")),
    *positive(("max_angular_velocity", "rad/s"), ("max_angular_acceleration", "rad/s²"),
              ("max_angular_jerk", "rad/s³")),
    Flag("friction_compensation"),
    Vector("external_wrench", "N, N·m", length=6),
)
TDA_FIELDS = (
    Choice("method", METHODS, field="tda_method"),
    Number("nu", "", field="tda_nu", minimum=0.0, maximum=1.0),
    Vector("direction", "", field="tda_direction"),
    Number("max_tension_rate", "N/s", positive=True),
)
SAFETY_FIELDS: tuple[Field, ...] = (
    *positive(("max_position_error", "m"), ("max_angle_error", "rad"), ("max_speed", "m/s"),
              ("max_feedback_age", "s"), ("stop_duration", "s"), ("max_saturation_time", "s")),
    Number("tension_margin", "N", minimum=0.0),
    Number("max_fk_residual", "m", positive=True),
    Number("max_tension_disagreement", "of the tension range", positive=True, maximum=1.0),
)
REALTIME_FIELDS = (
    Number("sleep_margin", "s", minimum=0.0, maximum=0.01),
    Number("sched_priority", "", minimum=1, maximum=99, integer=True),
    Number("cpu", "", minimum=-1, integer=True),
    Flag("lock_memory"),
    Flag("freeze_gc"),
    Number("cpu_wakeup_latency", "s", minimum=-1.0, maximum=0.01),
)


def read_control(
    rd: TableReader, data: dict[str, Any], cable_names: list[str]
) -> ControlConfig | None:
    def read(t: dict[str, Any], vals: dict[str, Any]) -> None:
        d = ControlConfig()
        read_fields(rd, t, "control", CONTROL_FIELDS, d, vals)
        tda = rd.table(t, "tda", "control", required=False)
        if tda is not None:
            rd.check_keys(tda, TDA_KEYS, "control.tda")
            read_fields(rd, tda, "control.tda", TDA_FIELDS, d, vals)
            vals["impositions"] = read_impositions(rd, tda, cable_names)
        for key, keys, fields in (("safety", SAFETY_KEYS, SAFETY_FIELDS),
                                  ("realtime", REALTIME_KEYS, REALTIME_FIELDS)):  # fmt: skip
            sub = rd.table(t, key, "control", required=False)
            if sub is not None:
                rd.check_keys(sub, keys, f"control.{key}")
                read_fields(rd, sub, f"control.{key}", fields, d, vals)

    return read_section(rd, data, "control", CONTROL_KEYS, ControlConfig, read)


def read_impositions(
    rd: TableReader, tda: dict[str, Any], cable_names: list[str]
) -> tuple[ImposeConfig, ...]:
    """``[[control.tda.impose]]``: the energy TDA's impositions, each on a cable by name."""
    tp = "control.tda"
    imps = tda.get("impose", [])
    if not isinstance(imps, list) or not all(isinstance(x, dict) for x in imps):
        rd.error(f"{tp}.impose", imps, "", "must be an array of tables")
        imps = []
    out = []
    for k, imp in enumerate(imps):
        ip = f"{tp}.impose[{k}]"
        rd.check_keys(imp, ("cable", "quantity", "value"), ip)
        cable = imp.get("cable")
        q = imp.get("quantity")
        v = rd.number(imp, "value", ip, {"energy": "J", "tension": "N"}.get(q, "m"))
        if cable not in cable_names:
            rd.error(f"{ip}.cable", cable, "", f"is not a cable ({', '.join(cable_names)})")
        elif q not in ("energy", "tension", "deformation"):
            rd.error(f"{ip}.quantity", q, "", "must be energy, tension or deformation")
        elif v is not None:
            out.append(ImposeConfig(cable_names.index(cable), q, v))
    return tuple(out)
