"""Command validation, in the gateway process (never in the loop's): every field checked for
type, finiteness, unit range, the workspace, the wrench-feasibility of a target pose and the
supervisor state. A rejection names the field, the value, the unit and the rule."""

from __future__ import annotations

import contextlib
import json
import math
from typing import Any

import numpy as np

from cdprctl.control.command_types import ACCEPTED_IN, CommandKind
from cdprctl.control.states import State
from cdprctl.core.angles import degrees_hint
from cdprctl.core.rotation import log_so3, rpy_to_matrix
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics, kinematics_ok
from cdprctl.geometry.stiffness import cable_stiffnesses
from cdprctl.model.control import METHODS
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.trajectory import pose_coordinates
from cdprctl.tda import (
    ImposedQuantity,
    Imposition,
    TDAMethod,
    TDAOptions,
    TensionDistributor,
    tda_options_of,
)
from cdprctl.tda.grip_range import travel_range

# the loop's kinds, and "impose", which the gateway turns into a set_tda
KINDS = (*(k.value for k in CommandKind), "impose")
# the controller's own acceptance table (control/command_types.py), as state names
ALLOWED_STATES = {
    k.value: tuple(s.value for s in State if s in states)
    for k, states in ACCEPTED_IN.items()
    if states != frozenset(State)
}
FIELDS: dict[str, dict[str, str]] = {  # field → unit, per kind ("id" is always allowed)
    "enable": {},
    "disable": {},
    "stop": {"category": ""},
    "reset": {},
    "move": {"position": "m", "rpy": "rad", "max_velocity": "m/s", "max_acceleration": "m/s²"},
    "set_tda": {"method": "", "nu": "", "direction": ""},
    "impose": {"cable": "", "quantity": "", "value": "J, N or m"},
    "gripper": {"gripper": "", "travel": "m", "force": "N", "release": ""},
    "jog": {"velocity": "m/s, rad/s", "frame": ""},
    "path": {"text": "", "name": ""},
    "pause": {},
    "resume": {},
    "abort": {},
}
MAX_PAYLOAD = 4096  # bytes
MAX_PATH_PAYLOAD = 1 << 20  # bytes: a path file travels in its command


class CommandError(Exception):
    pass


def _number(d: dict[str, Any], key: str, unit: str, lo: float, hi: float) -> float:
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise CommandError(f"{key} = {json.dumps(v)} must be a number ({unit})")
    x = float(v)
    if not math.isfinite(x):
        raise CommandError(f"{key} = {v} must be finite")
    if not lo <= x <= hi:
        raise CommandError(f"{key} = {x:g} {unit} must be in [{lo:g}, {hi:g}] {unit}".strip())
    return x


def _vector(d: dict[str, Any], key: str, unit: str, n: int = 3) -> np.ndarray:
    v = d[key]
    if (
        not isinstance(v, list)
        or len(v) != n
        or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    ):
        raise CommandError(f"{key} = {json.dumps(v)[:80]} must be a list of {n} numbers ({unit})")
    a = np.array(v, dtype=float)
    if not np.all(np.isfinite(a)):
        raise CommandError(f"{key} = {json.dumps(v)} must contain only finite numbers ({unit})")
    return a


def _stop_category(d: dict[str, Any]) -> int:
    """``{"category": 0|1|2}`` (IEC 60204-1; default 2: decelerate and hold)."""
    v = d.get("category", 2)
    if isinstance(v, bool) or v not in (0, 1, 2):
        raise CommandError(
            f"stop: category = {json.dumps(v)} must be 0 (the drives off at once, onto the "
            "brakes), 1 (decelerate, then off) or 2 (decelerate and hold)"
        )
    return int(v)


class CommandValidator:
    """``check(kind, payload, state)`` → (command kind, parameters) for the daemon, or raises
    :class:`CommandError` with the reason."""

    def __init__(self, model: RobotModel, commands_enabled: bool):
        self.model = model
        self.enabled = commands_enabled
        self.kin = KinematicsData(model)
        self.tda = TensionDistributor(model, tda_options_of(model))
        self.limits = SoftLimits(model)
        self._grip: GripperSet | None = None
        self._range_tda: TensionDistributor | None = None

    def warm_up(self) -> None:
        """The kernels a move's checks call (kinematics, the TDA, the soft limits) compiled or
        loaded now, at the gateway's start: at the first move of a first run (an empty kernel
        cache) they made its reply wait 5 s."""
        with contextlib.suppress(CommandError):
            self._move({"position": [float(v) for v in self.model.home.position]}, None)

    def parse(self, payload: bytes, kind: str = "") -> dict[str, Any]:
        limit = MAX_PATH_PAYLOAD if kind == "path" else MAX_PAYLOAD
        if len(payload) > limit:
            raise CommandError(f"payload of {len(payload)} bytes exceeds {limit} bytes")
        if not payload.strip():
            return {}
        try:
            d = json.loads(payload)
        except (ValueError, UnicodeDecodeError) as exc:
            raise CommandError(f"payload is not JSON ({exc})") from None
        if not isinstance(d, dict):
            raise CommandError(f"payload must be a JSON object, not {type(d).__name__}")
        return d

    def check(
        self, kind: str, d: dict[str, Any], state: str, snap: dict[str, Any] | None = None
    ) -> tuple[str, dict[str, Any]]:
        """``snap``: the loop's last snapshot (pose, grippers' targets), for the checks that
        depend on where the robot is now (a gripper's feasible travel)."""
        if not self.enabled:
            raise CommandError("commands are disabled: the daemon was started without "
                               "--accept-commands ([zenoh] commands = false; docs/telemetry.md)")
        if kind not in KINDS:
            raise CommandError(f"command {kind!r} is unknown (known: {', '.join(KINDS)})")
        allowed = FIELDS[kind]
        for key in d:
            if key != "id" and key not in allowed:
                known = ", ".join(sorted(allowed)) or "none"
                raise CommandError(f"field {key!r} is unknown (allowed: {known}, id)")
        if kind in ALLOWED_STATES and state not in ALLOWED_STATES[kind]:
            raise CommandError(
                f"{kind} is not accepted in state {state} "
                f"(only in: {', '.join(ALLOWED_STATES[kind])})"
            )
        if kind == "move":
            return "move", self._move(d, snap)
        if kind == "set_tda":
            return "set_tda", {"tda": self._set_tda(d)}
        if kind == "impose":
            return "set_tda", {"tda": self._impose(d)}
        if kind == "gripper":
            return "gripper", self._gripper(d, snap)
        if kind == "jog":
            return "jog", self._jog(d)
        if kind == "path":
            return "path", self._path(d, snap)
        if kind == "stop":
            return "stop", {"category": _stop_category(d)}
        return kind, {}

    def _jog(self, d: dict[str, Any]) -> dict[str, Any]:
        """``{"velocity": [vx, vy, vz, ωx, ωy, ωz] (m/s, rad/s), "frame": "base"|"platform"}``;
        repeat it at least every ``[control] jog_deadman`` s to keep moving."""
        c = self.model.control
        if "velocity" not in d:
            raise CommandError("jog: velocity [vx, vy, vz, wx, wy, wz] (m/s, rad/s) is required")
        v = _vector(d, "velocity", "m/s, rad/s", 6)
        for k in range(6):
            if k < 3:
                lim, unit, name = c.max_velocity, "m/s", "max_velocity"
            else:
                lim, unit, name = c.max_angular_velocity, "rad/s", "max_angular_velocity"
            if abs(v[k]) > lim:
                raise CommandError(f"velocity[{k}] = {v[k]:g} {unit} exceeds [control] {name} "
                                   f"= {lim:g} {unit}")  # fmt: skip
        frame = d.get("frame", "base")
        if frame not in ("base", "platform"):
            raise CommandError(f"frame = {json.dumps(frame)} must be \"base\" or \"platform\"")
        return {"velocity": v.tolist(), "frame": frame}

    def _path(self, d: dict[str, Any], snap: dict[str, Any] | None) -> dict[str, Any]:
        """``{"text": the CSV or G-code file, "name": where it came from}``: parsed and the
        whole path checked from where the robot rests now (the controller checks again from
        the reference it holds when the command arrives; a refusal there is an event)."""
        from cdprctl.motion.path_plan import PathRejectedError, plan_text
        from cdprctl.motion.waypoints import PathFileError

        text, name = d.get("text"), d.get("name", "")
        if not isinstance(text, str) or not text.strip():
            raise CommandError("path: text (the path file's content, CSV or G-code) is required")
        if not isinstance(name, str) or len(name) > 200:
            raise CommandError("path: name must be a string of at most 200 characters")
        plan = None
        if snap is not None and np.all(np.isfinite(snap["reference"])):
            try:
                plan = plan_text(self.model, text, np.asarray(snap["reference"], dtype=float),
                                 self.model.control.period, self.limits, name)  # fmt: skip
            except (PathFileError, PathRejectedError) as exc:
                raise CommandError(f"path {name}: {exc}") from None
        # the plan travels with the text: the daemon uses it when the robot still rests where
        # it was made (no second planning beside the loop), and plans again otherwise
        return {"text": text, "name": name, "plan": plan}

    def _move(self, d: dict[str, Any], snap: dict[str, Any] | None) -> dict[str, Any]:
        """A target pose checked where it is (the workspace, the tilt, the tensions, the soft
        limits) and, with the loop's snapshot, the straight line to it from the reference
        there (``SoftLimits.line_refusal``: the desk's own rule, which it checks again from
        the reference it holds when the command arrives)."""
        m, c, ws = self.model, self.model.control, self.model.workspace
        if "position" not in d:
            raise CommandError("position (m, base frame) is required")
        p = _vector(d, "position", "m")
        rpy = _vector(d, "rpy", "rad") if "rpy" in d else np.array(m.home.rpy, dtype=float)
        for k, a in enumerate(rpy):  # 30 typed for degrees wrapped to 1.4159 rad unsaid
            if hint := degrees_hint(k, f"{a:g}", float(a)):
                raise CommandError(f"rpy = {np.round(rpy, 4).tolist()} rad: {hint}")
        for i, axis in enumerate("xyz"):
            if not ws.position_min[i] <= p[i] <= ws.position_max[i]:
                raise CommandError(
                    f"position.{axis} = {p[i]:g} m is outside the workspace "
                    f"[{ws.position_min[i]:g}, {ws.position_max[i]:g}] m"
                )
        R = rpy_to_matrix(*rpy)
        angle = float(np.linalg.norm(log_so3(R @ m.home.rotation.T)))
        if angle > ws.max_angle:
            raise CommandError(
                f"rpy = {np.round(rpy, 4).tolist()} rad is {angle:.3f} rad "
                f"({math.degrees(angle):.2f}°) from the home orientation, more than "
                f"workspace.max_angle = {ws.max_angle:g} rad ({math.degrees(ws.max_angle):.2f}°)"
            )
        speed = accel = 1.0
        if "max_velocity" in d:
            speed = _number(d, "max_velocity", "m/s", 1e-6, c.max_velocity) / c.max_velocity
        if "max_acceleration" in d:
            a = _number(d, "max_acceleration", "m/s²", 1e-6, c.max_acceleration)
            accel = a / c.max_acceleration
        inverse_kinematics(m, self.kin, p, R)
        if not kinematics_ok(self.kin):
            raise CommandError(
                f"position = {p.tolist()} m: the cables' geometry is degenerate there"
            )
        hold = -(m.gravity_wrench(R) + np.asarray(c.external_wrench))
        out = self.tda.solve(self.kin.W, hold, k=cable_stiffnesses(m, self.kin), kin=self.kin)
        if not out.ok:
            raise CommandError(
                f"position = {np.round(p, 4).tolist()} m, rpy = {np.round(rpy, 4).tolist()} rad "
                f"cannot be held within the tension limits ({out.status.name}: {out.message})"
            )
        target = pose_coordinates(m, p, R)
        # the target alone: its box, tilt and tensions; the clearance it must keep depends on
        # where the motion starts (no closer than there, when that is under it): the line's
        # check below
        margin, ok = self.limits.check(target[None], clearance=False)
        where = f"position = {np.round(p, 4).tolist()} m, rpy = {np.round(rpy, 4).tolist()} rad"
        if not ok[0]:
            why = self.limits.why(target, float(margin[0]), clearance=False)
            raise CommandError(f"{where}: {why}")
        if snap is not None and np.all(np.isfinite(snap["reference"])):
            why = self.limits.line_refusal(snap["reference"], target)
            if why:
                raise CommandError(f"{where}: {why}")
        return {"pose": np.concatenate([p, rpy]).tolist(), "speed": speed, "accel": accel}

    def _gripper(self, d: dict[str, Any], snap: dict[str, Any] | None) -> dict[str, Any]:
        """``{"gripper": cable name, and one of "travel": m | "force": N | "release": true}``.
        A travel the redundancy cannot give at the pose of ``snap`` (the other grippers held
        at their targets) is refused with the feasible range; the controller checks again at
        the pose it holds when the command arrives (a refusal there is an event)."""
        gs = self.model.grippers
        if not gs:
            raise CommandError(f"robot {self.model.name} has no gripper in its config")
        names = [g.name for g in gs]
        name = d.get("gripper", names[0] if len(names) == 1 else None)
        if isinstance(name, int) and not isinstance(name, bool):  # `cdprctl send ... gripper=1`
            name = str(name)
        if name not in names:
            raise CommandError(
                f"gripper = {json.dumps(name)} must name a gripper's cable ({', '.join(names)})"
            )
        j = names.index(name)
        given = [k for k in ("travel", "force", "release") if k in d]
        if len(given) != 1:
            raise CommandError("gripper: give exactly one of travel (m), force (N), release")
        g = gs[j]
        if given[0] == "travel":
            v = _number(d, "travel", "m", 0.0, g.travel_max)
            lo, hi = self._travel_range(j, snap)
            if math.isfinite(lo) and not lo <= v <= hi:
                raise CommandError(
                    f"travel = {v:g} m is outside what the redundancy gives gripper {name} "
                    f"here: [{lo:.4f}, {hi:.4f}] m"
                )
        elif given[0] == "force":
            v = _number(d, "force", "N", 0.0, float(self.model.cables[g.cable].tension_max))
        else:
            if d["release"] is not True:
                raise CommandError(f"release = {json.dumps(d['release'])} must be true")
            v = 0.0
        return {"gripper": j, "grip": given[0], "value": v}

    def _travel_range(self, j: int, snap: dict[str, Any] | None) -> tuple[float, float]:
        if snap is None or not np.all(np.isfinite(snap["position"])):
            return math.nan, math.nan
        m, c = self.model, self.model.control
        R = rpy_to_matrix(*snap["rpy"])
        inverse_kinematics(m, self.kin, snap["position"], R)
        if self._grip is None:
            self._grip = GripperSet(m)
            self._range_tda = TensionDistributor(m, TDAOptions(method=TDAMethod.ENERGY))
        assert self._range_tda is not None
        return travel_range(
            m,
            self._range_tda,
            self._grip,
            j,
            np.asarray(snap["grip_target"], dtype=float),
            self.kin.W,
            R,
            cable_stiffnesses(m, self.kin),
            np.asarray(c.external_wrench, dtype=float),
            m.tension_min + c.tension_margin,
            m.tension_max - c.tension_margin,
        )

    def _options(self, opts: TDAOptions) -> TDAOptions:
        errs = opts.validate(self.model)
        if errs:
            raise CommandError("; ".join(errs))
        return opts

    def _set_tda(self, d: dict[str, Any]) -> TDAOptions:
        base = tda_options_of(self.model)
        method = d.get("method", base.method.value)
        if method not in METHODS:
            raise CommandError(f"method = {json.dumps(method)} must be one of {', '.join(METHODS)}")
        nu = _number(d, "nu", "", 0.0, 1.0) if "nu" in d else base.nu
        direction = base.direction
        if "direction" in d:  # plain floats: the message shows them as numbers
            direction = tuple(_vector(d, "direction", "").tolist())
        if np.linalg.norm(direction) < 1e-9:
            raise CommandError(f"direction = {list(direction)} must be a non-zero 3-vector")
        return self._options(
            TDAOptions(
                method=TDAMethod(method),
                nu=nu,
                direction=direction,
                impositions=base.impositions if method == "energy" else (),
                max_tension_rate=base.max_tension_rate,
                period=base.period,
            )
        )

    def _impose(self, d: dict[str, Any]) -> TDAOptions:
        names = [c.name for c in self.model.cables]
        for key in ("cable", "quantity", "value"):
            if key not in d:
                raise CommandError(f"impose: {key} is required")
        if d["cable"] not in names:
            raise CommandError(
                f"cable = {json.dumps(d['cable'])} is not a cable ({', '.join(names)})"
            )
        q = d["quantity"]
        if q not in [x.value for x in ImposedQuantity]:
            raise CommandError(f"quantity = {json.dumps(q)} must be energy, tension or deformation")
        unit = {"energy": "J", "tension": "N", "deformation": "m"}[q]
        value = _number(d, "value", unit, 0.0, 1e6)
        base = tda_options_of(self.model)
        return self._options(
            TDAOptions(
                method=TDAMethod.ENERGY,
                impositions=(Imposition(names.index(d["cable"]), ImposedQuantity(q), value),),
                max_tension_rate=base.max_tension_rate,
                period=base.period,
            )
        )
