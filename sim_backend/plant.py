"""The physics of the simulated robot: winches, elastic cables over swivel pulleys, platform.

Conventions (docs/simulator.md):

* Motor angle ``θ`` (rad, motor shaft) positive winds the cable in; a positive motor torque pulls
  the cable. The unstretched (paid-out) length of cable i is ``l0 = l_home − (r_d/G) θ``: the
  encoders are calibrated so that ``θ = 0`` is the unstretched length equal to the geometric
  length at the home pose.
* Cable: tension only, ``t = k_eff (l − l0) + c (dl/dt − dl0/dt)`` when taut, else 0, with
  ``k = E·S/(l0 + l_w)`` (or a fixed stiffness) in series with the optional spring; ``l`` the
  geometric length (free part + arc on the pulley). Pulley friction as a capstan factor
  ``exp(±μ β)`` on the winch side, by the direction the cable moves.
* Winch: ``J θ̈ = τ_m − (r_d/G) t_w − f(θ̇)``, ``f`` each winch's own friction (viscous,
  Coulomb, Stribeck: ``numerics.friction_law``, its terms the robot's as built: the as-built
  file or ``PlantErrors``, hidden from the controller); a closed brake holds ``θ``
  (a slipping brake, a fault, lets the drum pay out at a set rate). ``τ_m`` is the drive's
  torque: its target (torque mode), or its own position loop at every physics step around the
  target interpolated between SYNCs, plus a torque offset (position mode, CiA 402 CSP).
* Platform: a rigid body (mass, COM, inertia about the COM), Newton-Euler at the COM, gravity,
  an external wrench at ``P`` (force and moment, base frame).

Integrator: semi-implicit (symplectic) Euler at a fixed physics step (default 0.2 ms = 5 kHz),
compiled with numba (``physics.py``). Symplectic: for a conservative system the energy error
stays bounded instead of drifting (tested); the rotation is advanced with the exponential map.
This module holds the state, the set-up and the energy; ``physics.py`` the compiled steps,
``servo.py`` the drives' own loops within them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cdprctl.core.numerics import (
    cable_compliance_py,
    compliance_of,
    kernel_args,
    unstretched_lengths,
)
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.grippers import in_series
from cdprctl.model.robot import RobotModel
from cdprctl.tda.hold import equilibrium_tensions
from sim_backend.contact import ContactRecorder
from sim_backend.jaw_dynamics import Jaws, JawState
from sim_backend.physics import Body, BodyState, Inputs, Winches, physics_kernel
from sim_backend.servo import Servo


@dataclass
class PlantOptions:
    physics_dt: float = 0.0002  # s
    # μ of every pulley's capstan factor; None: each winch's own (``[winch] pulley_friction``)
    pulley_friction: float | None = None
    damping_ratio: float = (
        0.02  # cable damping as a fraction of critical (when the config has none)
    )
    coulomb_velocity: float = 0.05  # rad/s, smoothing of the Coulomb friction sign
    # grippers (Sensors 2019 §2.4): the cable jB and the guide's end stops are stiff springs
    jb_stiffness: float = 1.0e5  # N/m
    stop_stiffness: float = 1.0e5  # N/m
    jaw_damping_ratio: float = 0.3  # of critical, on jB, the stops and the contact
    jaw_friction_velocity: float = 0.002  # m/s, smoothing of the guide's Coulomb friction
    # a holding brake's torque as a multiple of its motor's torque limit: several times it
    # (a brake sized for the motor's peak torque, or on the gearbox's output): catching rowc
    # under a 400 N force beyond its capacity put up to 4.8 times the limit on its brakes
    # (12.4 N·m, lock-step); a brake test at the drive's limit passes
    brake_hold_factor: float = 5.0
    # s a holding brake takes to close once its power is cut (real ones: 10-50 ms); 0: at
    # once. Only where nothing holds the drum meanwhile — the safety chain's STO, which takes
    # the torque at once (``Cia402Axis.open_sto``); a drive disabling itself holds its motor
    # until the brake has closed, as drives sequence it (modelled as closing at once)
    brake_close_time: float = 0.0
    # a worn brake (``weaken_brake``, ``cdprctl brake-test --sim --weak-brake``): it holds this
    # fraction of its cable's worst-case load (the tension limit on the drum) — the platform at
    # rest, but not a brake test's 1.3 times that load
    weak_brake_fraction: float = 0.6


class CdprPlant:
    """State and parameters of the simulated robot; ``step(dt)`` integrates."""

    def __init__(self, model: RobotModel, options: PlantOptions | None = None):
        self.model = model
        self.opt = options or PlantOptions()
        m = model.n_cables
        self.m = m
        c = model.cables
        self.drum_ratio = np.array([w.winch.drum_radius / w.winch.gear_ratio for w in c])  # m/rad
        self.rotor_inertia = np.array([w.winch.rotor_inertia for w in c])
        self.viscous = np.array([w.winch.viscous_friction for w in c])
        self.coulomb = np.array([w.winch.coulomb_friction for w in c])
        self.stribeck = np.array([w.winch.stribeck_friction for w in c])
        mu = self.opt.pulley_friction
        self.pulley_friction = np.array(
            [w.winch.pulley_friction if mu is None else mu for w in c], dtype=float
        )
        self.law = compliance_of(c)  # the cable law's terms (cdprctl.core.numerics)
        self.kin = KinematicsData(model)
        inverse_kinematics(model, self.kin, model.home.position, model.home.rotation)
        self.l_home = self.kin.length.copy()
        k_home = model.cable_stiffness(self.l_home)
        # cable damping: the config's, else a fraction of the critical damping of the platform
        # mass spread over the cables
        crit = 2.0 * np.sqrt(k_home * model.platform.mass / m)
        self.damping = np.array(
            [
                x.damping if x.damping > 0 else self.opt.damping_ratio * crit[i]
                for i, x in enumerate(c)
            ]
        )
        self.mass = model.platform.mass
        self.com = np.array(model.platform.com)
        self.inertia = np.array(model.platform.inertia)
        self.gravity = np.array(model.gravity)
        # state
        self.com_pos = np.zeros(3)
        self.R = np.eye(3)
        self.v = np.zeros(3)
        self.w = np.zeros(3)
        self.theta = np.zeros(m)
        self.theta_dot = np.zeros(m)
        self.time = 0.0
        # inputs
        self.motor_torque = np.zeros(m)  # N·m, what the drives apply
        self.brake = np.ones(m, dtype=np.bool_)  # True: the drum is held
        self.brake_slip = np.zeros(m)  # rad/s at which a held drum slips (fault injection)
        # N·m at the motor a closed brake holds before it slips
        self.brake_hold = self.opt.brake_hold_factor * np.array([w.winch.torque_limit for w in c])
        self.cable_cut = np.zeros(m, dtype=np.bool_)
        self.drum_slip = np.zeros(m)  # m of cable slipped off the drum, unseen by the encoder
        self.ext_force = np.zeros(3)  # N at P, base frame
        self.ext_moment = np.zeros(3)  # N·m, base frame
        # the drives' position loops (CSP, ODrive's cascade; servo.Servo), set by the drives
        self.servo = Servo(
            np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m),
            np.array([w.winch.torque_limit for w in c]), np.zeros(m),
            np.full(m, np.inf), np.full(m, np.inf), np.zeros(m),
            np.zeros(m), np.full(m, np.inf), np.zeros(m), np.zeros(m),
        )  # fmt: skip
        self._init_grippers()
        # outputs of the last step
        self.tension = np.zeros(m)
        self._step_kin = KinematicsData(model)  # the physics steps' inverse kinematics
        self._bundle()
        self.set_pose(model.home.position, model.home.rotation, None)
        # the cables' contacts at the true pose, each step (contact.py)
        self.contact = ContactRecorder(model)

    def _bundle(self) -> None:
        """The kernels' bundles: the same arrays as the attributes (written in place)."""
        o = self.opt
        body = Body(self.com, float(self.mass), self.inertia, self.gravity)
        winches = Winches(
            self.l_home,
            self.drum_ratio,
            self.rotor_inertia,
            self.viscous,
            self.coulomb,
            self.stribeck,
            o.coulomb_velocity,
            self.law,
            self.damping,
            self.pulley_friction,
        )
        state = BodyState(self.com_pos, self.R, self.v, self.w, self.theta, self.theta_dot)
        inputs = Inputs(
            self.motor_torque,
            self.brake,
            self.brake_slip,
            self.brake_hold,
            self.cable_cut,
            self.drum_slip,
            self.ext_force,
            self.ext_moment,
        )
        jaws = Jaws(
            self.gripper_of_cable,
            self.g_cable,
            self.g_mass,
            self.g_jaw0,
            self.g_axis,
            self.g_friction,
            o.jaw_friction_velocity,
            self.g_travel_max,
            self.g_k_jb,
            self.g_c_jb,
            self.g_k_stop,
            self.g_c_stop,
            self.g_object_travel,
            self.g_k_contact,
            self.g_c_contact,
        )
        jaw_state = JawState(self.jaw_travel, self.jaw_speed, self.jb_tension, self.contact_force)
        self._args = tuple(kernel_args(b) for b in (body, winches, state, inputs, self.servo))
        self._jaw_args = (kernel_args(jaws), kernel_args(jaw_state))

    def _init_grippers(self) -> None:
        """Jaw bodies of the reconfigurable end-effector (``[[grippers]]``): each a point mass
        on a 1-DOF guide fixed to the platform, pulled along it by ``jB`` (Sensors 2019 §2.4,
        Fig. 1-3, 18), with its end stops, Coulomb friction and the object met at ``L21``."""
        gs = self.model.grippers
        ng = len(gs)
        o = self.opt
        self.g_cable = np.array([g.cable for g in gs], dtype=np.int64)
        self.gripper_of_cable = np.full(self.m, -1, dtype=np.int64)
        self.gripper_of_cable[self.g_cable] = np.arange(ng)
        self._grippers = GripperSet(self.model)
        self.g_mass = np.array([g.jaw_mass for g in gs])
        # jaw at zero travel, platform frame, relative to P; the guide's unit vector
        self.g_jaw0 = np.array(
            [self.model.attachments[g.cable] + g.jaw_offset for g in gs]
        ).reshape(ng, 3)
        self.g_axis = np.array([g.guide_axis for g in gs]).reshape(ng, 3)
        self.g_friction = np.array([g.guide_friction for g in gs])
        self.g_travel_max = np.array([g.travel_max for g in gs])
        self.g_k_jb = np.full(ng, o.jb_stiffness)
        self.g_k_stop = np.full(ng, o.stop_stiffness)
        crit = 2.0 * np.sqrt(o.jb_stiffness * np.maximum(self.g_mass, 1e-9))
        self.g_c_jb = o.jaw_damping_ratio * crit
        self.g_c_stop = o.jaw_damping_ratio * crit
        # the object: met at free_travel, stiffness K_B in series with its own
        self.g_object_travel = np.zeros(ng)
        self.g_k_contact = np.zeros(ng)
        self.g_c_contact = np.zeros(ng)
        for j, g in enumerate(gs):
            self.set_object(j, g.free_travel, g.object_stiffness)
        # state and outputs
        self.jaw_travel = np.zeros(ng)  # m along the guide from the lower end stop
        self.jaw_speed = np.zeros(ng)  # m/s
        self.jb_tension = np.zeros(ng)  # N
        self.contact_force = np.zeros(ng)  # N, jaw on the object

    def set_object(self, gripper: int, travel: float, stiffness: float) -> None:
        """Put an object in gripper ``gripper``'s way: met at ``travel`` (m, the L21 it makes),
        ``stiffness`` (N/m, in series with K_B; ``inf`` rigid, ``travel`` beyond the guide for
        none)."""
        k = in_series(self.model.grippers[gripper].k_b, stiffness)
        self.g_object_travel[gripper] = travel
        self.g_k_contact[gripper] = k
        self.g_c_contact[gripper] = (
            self.opt.jaw_damping_ratio * 2.0 * math.sqrt(k * self.g_mass[gripper])
        )

    def _settle_grippers(self, tensions: FloatArray, lengths: FloatArray, l0: FloatArray) -> None:
        """Static jaws under the cable tensions ``tensions`` (N): ``τ = K_A δ + τ_B``,
        ``τ_B = F∥ + F_c(q)``, ``q = δ − τ_B/k_jB`` (eq. (25)-(26) with a stiff jB); writes
        the unstretched lengths ``l0`` (m) of the gripper cables."""
        parallel = self._grippers.parallel_load(self.R)
        for j, i in enumerate(self.g_cable):
            ka, kjb = 1.0 / self.law.inv_k_fixed[i], self.g_k_jb[j]
            f_par = float(parallel[j])
            t = float(tensions[i])
            kc, L = self.g_k_contact[j], self.g_object_travel[j]
            q = (t - f_par) / ka - f_par / kjb  # no contact
            if q > L:
                q = ((t - f_par + kc * L) / ka - (f_par - kc * L) / kjb) / (1 + kc / ka + kc / kjb)
            q = min(max(q, 0.0), self.g_travel_max[j])
            tb = f_par + (kc * (q - L) if q > L else 0.0)
            delta = q + tb / kjb
            l0[i] = lengths[i] - delta
            self.jaw_travel[j] = q
            self.jaw_speed[j] = 0.0
            self.jb_tension[j] = tb
            self.contact_force[j] = tb - f_par

    # -- set-up -------------------------------------------------------------------------------
    def set_pose(self, position: FloatArray, R: FloatArray, tensions: FloatArray | None) -> None:
        """Platform at rest at ``(position, R)``; cables pre-tensioned to ``tensions`` (N) by
        choosing the motor angles; brakes closed. Default tensions: the equilibrium the
        controller will find (the robot's own TDA under gravity, ``equilibrium_tensions``), so
        a start is neither a fall nor a step of the drives' targets."""
        model = self.model
        inverse_kinematics(model, self.kin, position, R)
        if tensions is None:
            tensions = equilibrium_tensions(model, self.kin)
        t = np.asarray(tensions, float)
        length = self.kin.length
        l0 = unstretched_lengths(self.law, length, t)
        self.R[:] = R
        self._settle_grippers(t, length, l0)
        self.theta[:] = (self.l_home - l0) / self.drum_ratio
        self.theta_dot[:] = 0.0
        self.com_pos[:] = position + R @ self.com
        self.v[:] = 0.0
        self.w[:] = 0.0
        self.brake[:] = True
        self.tension[:] = t

    def close_brake(self, c: int) -> None:
        """Cable index ``c``'s brake closes: the drum stops at once (an ideal brake's
        engagement; it slips only on a torque beyond ``brake_hold``)."""
        if not self.brake[c]:
            self.theta_dot[c] = 0.0
        self.brake[c] = True

    def weaken_brake(self, c: int) -> None:
        """Cable index ``c``'s brake worn: it holds ``weak_brake_fraction`` of the cable's
        worst-case load torque (N·m at the motor: tension limit × drum radius / gear)."""
        self.brake_hold[c] = (
            self.opt.weak_brake_fraction * self.model.tension_max[c] * self.drum_ratio[c]
        )

    @property
    def position(self) -> FloatArray:
        """Platform reference point P (m, base frame)."""
        return self.com_pos - self.R @ self.com

    @property
    def cable_lengths(self) -> FloatArray:
        """Geometric cable lengths (m) at the last physics step."""
        return self._step_kin.length

    @property
    def wrench_matrix(self) -> FloatArray:
        """W (6 × m, base frame, about P) at the last physics step."""
        return self._step_kin.W

    def unstretched_length(self) -> FloatArray:
        return self.l_home - self.drum_ratio * self.theta + self.drum_slip

    # -- integration --------------------------------------------------------------------------
    def step(self, duration: float) -> None:
        """Advance ``duration`` seconds in physics steps of ``options.physics_dt``."""
        n = max(1, round(duration / self.opt.physics_dt))
        dt = duration / n
        body, winches, state, inputs, servo = self._args
        jaws, jaw_state = self._jaw_args
        physics_kernel(
            n,
            dt,
            self._step_kin.arrays,
            body,
            winches,
            state,
            inputs,
            servo,
            self.tension,
            jaws,
            jaw_state,
        )
        self.time += duration
        self.contact.update(self.time, self.position, self.R)

    def energy(self) -> float:
        """Kinetic + cable elastic + gravity potential energy (J), winches included; for the
        drift test (cable damping and friction make it decrease)."""
        inverse_kinematics(self.model, self.kin, self.position, self.R)
        e = 0.5 * self.mass * float(self.v @ self.v)
        Iw = self.R @ self.inertia @ self.R.T
        e += 0.5 * float(self.w @ Iw @ self.w)
        e += 0.5 * float(np.sum(self.rotor_inertia * self.theta_dot**2))
        e -= self.mass * float(self.gravity @ self.com_pos)
        l0 = self.unstretched_length()
        stretch = self.kin.length - l0
        law = self.law
        for i in range(self.m):
            if stretch[i] > 0 and not self.cable_cut[i]:
                c = cable_compliance_py(
                    law.inv_k_fixed[i], law.inv_es[i], law.l_winch[i], law.inv_spring[i], l0[i]
                )
                k = 1.0 / c
                e += 0.5 * k * stretch[i] ** 2
        return e + self._jaw_energy(stretch)

    def jaw_positions(self) -> FloatArray:
        """(grippers, 3) m, base frame: where each jaw is."""
        k = self.g_axis @ self.R.T
        return self.position + self.g_jaw0 @ self.R.T + self.jaw_travel[:, None] * k

    def _jaw_energy(self, stretch: FloatArray) -> float:
        """Kinetic and potential energy (J) of the jaws, jB, the object and the stops."""
        e = 0.0
        x = self.jaw_positions()
        for j, i in enumerate(self.g_cable):
            k = self.R @ self.g_axis[j]
            r = x[j] - self.com_pos
            vj = self.v + np.cross(self.w, r) + self.jaw_speed[j] * k
            e += 0.5 * self.g_mass[j] * float(vj @ vj) - self.g_mass[j] * float(self.gravity @ x[j])
            q = self.jaw_travel[j]
            e += 0.5 * self.g_k_jb[j] * max(stretch[i] - q, 0.0) ** 2
            e += 0.5 * self.g_k_contact[j] * max(q - self.g_object_travel[j], 0.0) ** 2
            e += (
                0.5
                * self.g_k_stop[j]
                * (min(q, 0.0) ** 2 + max(q - self.g_travel_max[j], 0.0) ** 2)
            )
        return e
