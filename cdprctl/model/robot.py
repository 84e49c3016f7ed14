"""The robot description: frozen dataclasses built once by :mod:`cdprctl.robot_file.loader`.

All quantities are SI. Frames: ``base`` is the fixed world frame of the robot (z up);
``platform`` is the moving-platform frame, whose origin ``P`` is the platform's reference point
(the point the pose, the wrench and the moments refer to).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdprctl.core.numerics import cable_compliance_py, compliance_terms
from cdprctl.core.rotation import FloatArray, cross3, rpy_to_matrix
from cdprctl.model.calibration import CalibrationConfig
from cdprctl.model.control import ControlConfig
from cdprctl.model.drives import DrivesConfig
from cdprctl.model.foxglove import FoxgloveConfig
from cdprctl.model.grippers import Gripper
from cdprctl.model.interference import InterferenceConfig
from cdprctl.model.paths import PathsConfig
from cdprctl.model.ros2 import Ros2Config
from cdprctl.model.safety import SafetyConfig
from cdprctl.model.sensors import SensorsConfig
from cdprctl.model.zenoh import ZenohConfig


def _frozen(a: FloatArray) -> FloatArray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Pulley:
    """A swivel pulley at a cable's exit.

    The cable arrives from the winch along the swivel axis, through the cable's ``anchor`` point,
    travelling in the direction ``axis`` (unit vector, base frame); the pulley turns about that
    axis to face the platform, the cable wraps over the wheel of radius ``radius`` (m) and leaves
    it tangentially towards the platform.
    """

    radius: float
    axis: FloatArray


@dataclass(frozen=True)
class Winch:
    """Winch and drive parameters, motor side unless stated."""

    drum_radius: float  # m
    gear_ratio: float  # motor revolutions per drum revolution
    rotor_inertia: float  # kg·m², motor + gearbox + drum reflected to the motor shaft
    viscous_friction: float  # N·m·s/rad at the motor shaft
    coulomb_friction: float  # N·m at the motor shaft
    torque_limit: float  # N·m, motor
    encoder_counts_per_rev: int  # counts per motor revolution
    # N·m at the motor: the breakaway friction beyond the Coulomb level near zero speed
    # (``numerics.friction_law``)
    stribeck_friction: float = 0.0
    pulley_friction: float = 0.0  # μ of the capstan loss over the cable's swivel pulley

    @property
    def max_cable_force(self) -> float:
        """Largest cable tension (N) the motor torque limit can hold, friction neglected."""
        return self.torque_limit * self.gear_ratio / self.drum_radius


@dataclass(frozen=True)
class Cable:
    """One cable: exit point on the frame, attachment on the platform, limits, elasticity."""

    name: str
    anchor: FloatArray  # m, base frame: exit point (or swivel-axis point when ``pulley`` is set)
    attachment: FloatArray  # m, platform frame
    tension_min: float  # N
    tension_max: float  # N
    stiffness: float | None  # N/m, fixed axial stiffness (exclusive with E·S)
    youngs_modulus: float | None  # Pa
    cross_section: float | None  # m²
    spring_stiffness: float | None  # N/m, optional spring in series with the cable
    damping: float  # N·s/m, axial
    length_to_winch: float  # m, cable between drum and exit point, counted in k = E·S/l
    pulley: Pulley | None
    winch: Winch

    def axial_stiffness(self, length: float) -> float:
        """Axial stiffness (N/m) of cable + series spring at geometric length ``length`` (m)
        (``cdprctl.core.numerics.cable_compliance``; the loader guarantees E and S are set whenever
        ``stiffness`` is not)."""
        return 1.0 / cable_compliance_py(*compliance_terms(self), length)


@dataclass(frozen=True)
class Platform:
    mass: float  # kg
    com: FloatArray  # m, platform frame
    inertia: FloatArray  # kg·m², 3×3 about the COM, platform frame


@dataclass(frozen=True)
class Pose:
    """Platform pose: position of ``P`` (m, base frame) and roll-pitch-yaw (rad)."""

    position: FloatArray
    rpy: FloatArray

    @property
    def rotation(self) -> FloatArray:
        return rpy_to_matrix(float(self.rpy[0]), float(self.rpy[1]), float(self.rpy[2]))


@dataclass(frozen=True)
class Workspace:
    """Box the controller keeps the platform's reference point in, and the largest tilt."""

    position_min: FloatArray  # m, base frame
    position_max: FloatArray  # m, base frame
    max_angle: float  # rad, largest rotation angle away from the home orientation
    # N: a target (a move's, a jog's, a path's) must be held with the best distribution this
    # far from every tension limit; None: the TDA's tension_margin + 1 % of the smallest range
    wrench_margin: float | None = None


@dataclass(frozen=True)
class RobotModel:
    """The frozen robot description, plus arrays stacked once for the numerical core."""

    name: str
    source: str
    source_file: str
    gravity: FloatArray  # m/s², base frame
    platform: Platform
    cables: tuple[Cable, ...]
    home: Pose
    workspace: Workspace
    drives: DrivesConfig
    control: ControlConfig
    zenoh: ZenohConfig = field(default_factory=ZenohConfig)
    foxglove: FoxgloveConfig = field(default_factory=FoxgloveConfig)
    ros2: Ros2Config = field(default_factory=Ros2Config)
    # Sensors 2019 §2.4 end-effector (cdprctl.geometry.gripper_mechanics)
    grippers: tuple[Gripper, ...] = ()
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    paths: PathsConfig = field(default_factory=PathsConfig)  # how path files are read
    # the platform's body, the cell's obstacles, the clearance (cdprctl/geometry/interference.py)
    interference: InterferenceConfig = field(default_factory=InterferenceConfig)
    # load cells on cables (docs/config.md, "Load cells")
    sensors: SensorsConfig = field(default_factory=SensorsConfig)
    # Stacked per-cable arrays (derived in __post_init__; read-only).
    anchors: FloatArray = field(init=False, repr=False)  # (m, 3) base frame
    attachments: FloatArray = field(init=False, repr=False)  # (m, 3) platform frame
    tension_min: FloatArray = field(init=False, repr=False)  # (m,) N
    tension_max: FloatArray = field(init=False, repr=False)  # (m,) N
    pulley_radius: FloatArray = field(init=False, repr=False)  # (m,) m, 0 without pulley
    pulley_axis: FloatArray = field(init=False, repr=False)  # (m, 3) unit, zeros without pulley

    def __post_init__(self) -> None:
        cables = self.cables
        set_ = object.__setattr__  # frozen dataclass: derived fields are set once, here
        set_(self, "anchors", _frozen(np.array([c.anchor for c in cables])))
        set_(self, "attachments", _frozen(np.array([c.attachment for c in cables])))
        set_(self, "tension_min", _frozen(np.array([c.tension_min for c in cables])))
        set_(self, "tension_max", _frozen(np.array([c.tension_max for c in cables])))
        set_(
            self,
            "pulley_radius",
            _frozen(np.array([c.pulley.radius if c.pulley else 0.0 for c in cables])),
        )
        set_(
            self,
            "pulley_axis",
            _frozen(np.array([c.pulley.axis if c.pulley else np.zeros(3) for c in cables])),
        )

    @property
    def n_cables(self) -> int:
        return len(self.cables)

    @property
    def redundancy(self) -> int:
        """Degree of actuation redundancy r = m − 6."""
        return len(self.cables) - 6

    @property
    def has_pulleys(self) -> bool:
        return any(c.pulley is not None for c in self.cables)

    def cable_stiffness(self, lengths: FloatArray) -> FloatArray:
        """Axial stiffness k_i (N/m) of every cable at geometric lengths ``lengths`` (m)."""
        return np.array([c.axial_stiffness(float(lengths[i])) for i, c in enumerate(self.cables)])

    @property
    def soft_margin(self) -> float:
        """N: the tension margin every target keeps (``[workspace] wrench_margin``)."""
        if self.workspace.wrench_margin is not None:
            return self.workspace.wrench_margin
        span = float(np.min(self.tension_max - self.tension_min))
        return self.control.tension_margin + 0.01 * span

    def gravity_wrench(self, R: FloatArray) -> FloatArray:
        """Wrench of gravity on the platform (N, N·m), base frame, moments about ``P``.

        ``R`` is the platform orientation (platform → base).
        """
        f = self.platform.mass * self.gravity
        r = R @ self.platform.com
        return np.concatenate([f, cross3(r, f)])
