"""Input options, status codes and output of the tension distribution (ruckig-style).

Options are validated once, outside the loop (:meth:`TDAOptions.validate`); the in-loop
:meth:`~cdprctl.tda.solver.TensionDistributor.solve` never raises and never returns NaN or
out-of-limit tensions with status ``OK``.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from cdprctl.core.rotation import FloatArray

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel


class TDAMethod(enum.StrEnum):
    PINV = "pinv"  # minimum-norm, limits ignored (baseline)
    CLOSED_FORM = "closed-form"  # Pott 2014, improved closed form
    BARYCENTER = "barycenter"  # area centroid of the feasible polygon (r = 2)
    MIN_2NORM = "min-2-norm"  # bounded minimum 2-norm (r = 2: polygon; else QP)
    MIN_1NORM = "min-1-norm"  # bounded minimum 1-norm = smallest tension sum (r = 2)
    SOTDA = "sotda"  # Picard et al. 2020, Algorithm 1, with ν (r = 2)
    ENERGY = "energy"  # Sensors 2019 §2: impositions + minimum total energy (any r)
    QP = "qp"  # bounded minimum 2-norm by a dense QP solver (any r)


POLYGON_METHODS = frozenset({TDAMethod.BARYCENTER, TDAMethod.MIN_1NORM, TDAMethod.SOTDA})


class TDAStatus(enum.IntEnum):
    OK = 0
    OUT_OF_LIMITS = 1  # equilibrium exact, some tension outside its limits (pinv baseline)
    INFEASIBLE = 2  # no tensions within limits give the wrench: least-violating returned
    IMPOSITION_INFEASIBLE = 3  # impositions unreachable within limits: minimum energy without them
    DEGENERATE = 4  # wrench matrix rank-deficient, or non-finite input: no tensions
    INTERNAL_ERROR = 5  # an unexpected exception, caught: no tensions


# Each member bound to a name once: on Python 3.11 reading ``TDAStatus.X`` goes through
# ``EnumType.__getattr__``, which builds a method wrapper per read (3.12 dropped it): the
# control cycle's solve reads these (tests/control/cycle/test_allocations.py).
OK, OUT_OF_LIMITS, INFEASIBLE = TDAStatus.OK, TDAStatus.OUT_OF_LIMITS, TDAStatus.INFEASIBLE
IMPOSITION_INFEASIBLE, DEGENERATE, INTERNAL_ERROR = (
    TDAStatus.IMPOSITION_INFEASIBLE, TDAStatus.DEGENERATE, TDAStatus.INTERNAL_ERROR
)  # fmt: skip
PINV, CLOSED_FORM, BARYCENTER = TDAMethod.PINV, TDAMethod.CLOSED_FORM, TDAMethod.BARYCENTER
MIN_2NORM, MIN_1NORM, SOTDA = TDAMethod.MIN_2NORM, TDAMethod.MIN_1NORM, TDAMethod.SOTDA
ENERGY, QP = TDAMethod.ENERGY, TDAMethod.QP


class ImposedQuantity(enum.StrEnum):
    ENERGY = "energy"  # J, U_i = t_i²/(2 k_i)  (Sensors 2019, eq. (4))
    TENSION = "tension"  # N
    DEFORMATION = "deformation"  # m, δ_i = t_i/k_i  (Sensors 2019, eq. (3))


UNITS = {
    ImposedQuantity.ENERGY: "J",
    ImposedQuantity.TENSION: "N",
    ImposedQuantity.DEFORMATION: "m",
}


@dataclass(frozen=True)
class Imposition:
    """Impose ``quantity = value`` on cable ``cable`` (0-based index)."""

    cable: int
    quantity: ImposedQuantity
    value: float

    def tension(self, k: float) -> float:
        """The tension (N) this imposition means for a cable of stiffness ``k`` (N/m)."""
        if self.quantity is ImposedQuantity.TENSION:
            return self.value
        if self.quantity is ImposedQuantity.DEFORMATION:
            return k * self.value  # Sensors 2019, eq. (3)
        return math.sqrt(2.0 * k * max(self.value, 0.0))  # eq. (4), positive root


@dataclass(frozen=True)
class TDAOptions:
    """What to compute. Build, then :meth:`validate` against the robot before the loop."""

    method: TDAMethod = TDAMethod.BARYCENTER
    nu: float = 0.0  # SOTDA intermediate solution: 0 = barycenter, 1 = stiffness-oriented
    direction: tuple[float, float, float] = (0.0, 1.0, 0.0)  # SOTDA: minimise δp along it
    delta_wrench: tuple[float, ...] | None = None  # SOTDA δw_e (N, N·m); default 1 N along it
    sotda_variant: str = "vertices"  # "vertices" (real time) or "grid" (full search)
    grid_points: int = 60  # SOTDA grid per axis
    impositions: tuple[Imposition, ...] = ()
    max_tension_rate: float | None = None  # N/s, per cable
    period: float = 0.002  # s, control period (for the tension rate limit)

    def validate(self, model: RobotModel) -> list[str]:
        """Problems of these options for ``model`` (empty when usable), each naming the
        option, its value, unit and rule."""
        errs: list[str] = []
        r = model.redundancy
        m = model.n_cables
        if self.method in POLYGON_METHODS and r != 2:
            errs.append(
                f"method = {self.method.value} needs redundancy 2 (the feasible polygon), "
                f"the robot has r = {r}: use qp or energy"
            )
        if not (math.isfinite(self.nu) and 0.0 <= self.nu <= 1.0):
            errs.append(f"nu = {self.nu} must be in [0, 1]")
        d = np.asarray(self.direction, dtype=float)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-12:
            errs.append(f"direction = {list(self.direction)} must be a non-zero 3-vector")
        if self.delta_wrench is not None:
            dw = np.asarray(self.delta_wrench, dtype=float)
            if dw.shape != (6,) or not np.all(np.isfinite(dw)) or not np.any(dw):
                errs.append(
                    f"delta_wrench = {list(self.delta_wrench)} (N, N·m) must be 6 finite "
                    "numbers, not all zero"
                )
        if self.sotda_variant not in ("vertices", "grid"):
            errs.append(f"sotda_variant = {self.sotda_variant!r} must be 'vertices' or 'grid'")
        if not 2 <= self.grid_points <= 2000:
            errs.append(f"grid_points = {self.grid_points} must be in [2, 2000]")
        if self.max_tension_rate is not None and not (
            math.isfinite(self.max_tension_rate) and self.max_tension_rate > 0.0
        ):
            errs.append(f"max_tension_rate = {self.max_tension_rate} N/s must be > 0")
        if not (math.isfinite(self.period) and self.period > 0.0):
            errs.append(f"period = {self.period} s must be > 0")
        if self.impositions and self.method is not TDAMethod.ENERGY:
            errs.append("impositions need method = energy")
        if len(self.impositions) > r:
            errs.append(
                f"{len(self.impositions)} impositions: at most r = {r} (one per redundant "
                "degree of freedom, Sensors 2019 §2.3)"
            )
        seen: set[int] = set()
        for imp in self.impositions:
            if not 0 <= imp.cable < m:
                errs.append(f"impose cable index {imp.cable} must be in [0, {m - 1}]")
                continue
            if imp.cable in seen:
                errs.append(f"impose cable {model.cables[imp.cable].name}: imposed twice")
            seen.add(imp.cable)
            c = model.cables[imp.cable]
            unit = UNITS[imp.quantity]
            if not math.isfinite(imp.value) or imp.value < 0.0:
                errs.append(
                    f"impose cable {c.name} {imp.quantity.value} = {imp.value} {unit} must be "
                    "finite and >= 0"
                )
                continue
            if imp.quantity is ImposedQuantity.TENSION and not (
                c.tension_min <= imp.value <= c.tension_max
            ):
                errs.append(
                    f"impose cable {c.name} tension = {imp.value:g} N is outside "
                    f"[{c.tension_min:g}, {c.tension_max:g}] N"
                )
        return errs


@dataclass
class TDAOutput:
    """Result of one solve; arrays preallocated once and overwritten."""

    n_cables: int
    redundancy: int
    tensions: FloatArray = field(init=False)  # N, cable order of the model
    lam: FloatArray = field(init=False)  # null-space coordinates (basis of NullSpace)
    status: TDAStatus = TDAStatus.DEGENERATE
    residual: float = math.inf  # ‖W t − w‖ / max(1, ‖w‖)
    max_violation: float = 0.0  # N, largest bound violation (> 0 only when not OK)
    rate_limited: bool = False  # the tension-rate limit moved the solution
    polygon: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))  # λ vertices (r = 2)
    area: float = 0.0
    barycenter: tuple[float, float] = (math.nan, math.nan)
    energies: FloatArray = field(init=False)  # J, per cable, t²/(2k) (when k is given)
    energy_total: float = math.nan  # J
    energy_range: FloatArray = field(init=False)  # J, (m, 2) feasible range per free cable
    free_directions: FloatArray = field(init=False)  # (m, r − #impositions) tension directions
    segment_ends: FloatArray = field(init=False)  # (2, m) N: ends of the feasible segment
    sotda_displacement: float = math.nan  # m, δp along the direction at the solution
    message: str = ""

    def __post_init__(self) -> None:
        m, r = self.n_cables, self.redundancy
        self.tensions = np.zeros(m)
        self.lam = np.zeros(max(r, 0))
        self.energies = np.full(m, math.nan)
        self.energy_range = np.full((m, 2), math.nan)
        self.free_directions = np.zeros((m, 0))
        self.segment_ends = np.full((2, m), math.nan)

    @property
    def ok(self) -> bool:
        return self.status == TDAStatus.OK


def tda_options_of(model: RobotModel) -> TDAOptions:
    """The options the robot file's ``[control]`` asks for."""
    c = model.control
    return TDAOptions(
        method=TDAMethod(c.tda_method),
        nu=c.tda_nu,
        direction=c.tda_direction,
        impositions=tuple(
            Imposition(i.cable, ImposedQuantity(i.quantity), i.value) for i in c.impositions
        ),
        max_tension_rate=c.max_tension_rate,
        period=c.period,
    )
