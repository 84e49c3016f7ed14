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
* Winch: ``J θ̈ = τ_m − (r_d/G) t_w − b θ̇ − τ_c tanh(θ̇/ω_ε)``; a closed brake holds ``θ``
  (a slipping brake, a fault, lets the drum pay out at a set rate).
* Platform: a rigid body (mass, COM, inertia about the COM), Newton-Euler at the COM, gravity,
  an external wrench at ``P`` (force and moment, base frame).

Integrator: semi-implicit (symplectic) Euler at a fixed physics step (default 0.2 ms = 5 kHz),
compiled with numba. Symplectic: for a conservative system the energy error stays bounded
instead of drifting (tested); the rotation is advanced with the exponential map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from cdprctl.gripper import GripperSet
from cdprctl.kinematics import KinematicsData, ik_kernel, inverse_kinematics
from cdprctl.model.grippers import in_series
from cdprctl.model.robot import RobotModel
from cdprctl.numerics import cable_compliance, cable_compliance_py, compliance_terms
from cdprctl.rotation import FloatArray, exp_so3_kernel


@dataclass
class PlantOptions:
    physics_dt: float = 0.0002  # s
    pulley_friction: float = 0.0  # μ of the capstan factor
    damping_ratio: float = (
        0.02  # cable damping as a fraction of critical (when the config has none)
    )
    coulomb_velocity: float = 0.05  # rad/s, smoothing of the Coulomb friction sign
    # grippers (Sensors 2019 §2.4): the cable jB and the guide's end stops are stiff springs
    jb_stiffness: float = 1.0e5  # N/m
    stop_stiffness: float = 1.0e5  # N/m
    jaw_damping_ratio: float = 0.3  # of critical, on jB, the stops and the contact
    jaw_friction_velocity: float = 0.002  # m/s, smoothing of the guide's Coulomb friction


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
        # the cable law's terms (cdprctl.numerics.cable_compliance), per cable
        terms = np.array([compliance_terms(x) for x in c]).reshape(len(c), 4)
        self.inv_k_fixed, self.inv_es, self.l_winch, self.inv_spring = (
            np.ascontiguousarray(terms[:, j]) for j in range(4)
        )
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
        self.cable_cut = np.zeros(m, dtype=np.bool_)
        self.drum_slip = np.zeros(m)  # m of cable slipped off the drum, unseen by the encoder
        self.ext_force = np.zeros(3)  # N at P, base frame
        self.ext_moment = np.zeros(3)  # N·m, base frame
        self._init_grippers()
        # outputs of the last step
        self.tension = np.zeros(m)
        self._scratch = (
            np.zeros((3, m)),
            np.zeros((3, m)),
            np.zeros((3, m)),
            np.zeros(m),
            np.zeros(m),
            np.zeros(m),
            np.zeros((6, m)),
        )
        self.set_pose(model.home.position, model.home.rotation, None)

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
            ka, kjb = 1.0 / self.inv_k_fixed[i], self.g_k_jb[j]
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
        controller will find (the barycenter TDA under gravity), so a start is not a fall."""
        model = self.model
        inverse_kinematics(model, self.kin, position, R)
        if tensions is None:
            tensions = equilibrium_tensions(model, self.kin)
        t = np.asarray(tensions, float)
        length = self.kin.length
        # unstretched length l0 giving tension t at geometric length l, the cable law solved
        # for l0: l = l0 + t (1/k + (l0 + l_w)/(E S) + 1/k_s)
        c0 = self.inv_k_fixed + self.inv_es * self.l_winch + self.inv_spring
        l0 = (length - t * c0) / (1.0 + t * self.inv_es)
        self.R[:] = R
        self._settle_grippers(t, length, l0)
        self.theta[:] = (self.l_home - l0) / self.drum_ratio
        self.theta_dot[:] = 0.0
        self.com_pos[:] = position + R @ self.com
        self.v[:] = 0.0
        self.w[:] = 0.0
        self.brake[:] = True
        self.tension[:] = t

    @property
    def position(self) -> FloatArray:
        """Platform reference point P (m, base frame)."""
        return self.com_pos - self.R @ self.com

    @property
    def cable_lengths(self) -> FloatArray:
        """Geometric cable lengths (m) at the last physics step."""
        return self._scratch[5]

    @property
    def wrench_matrix(self) -> FloatArray:
        """W (6 × m, base frame, about P) at the last physics step."""
        return self._scratch[6]

    def unstretched_length(self) -> FloatArray:
        return self.l_home - self.drum_ratio * self.theta + self.drum_slip

    # -- integration --------------------------------------------------------------------------
    def step(self, duration: float) -> None:
        """Advance ``duration`` seconds in physics steps of ``options.physics_dt``."""
        n = max(1, round(duration / self.opt.physics_dt))
        dt = duration / n
        k = self.kin
        physics_kernel(
            n,
            dt,
            k.anchors,
            k.attachments,
            k.pulley_radius,
            k.pulley_axis,
            self.com,
            self.mass,
            self.inertia,
            self.gravity,
            self.l_home,
            self.drum_ratio,
            self.rotor_inertia,
            self.viscous,
            self.coulomb,
            self.opt.coulomb_velocity,
            self.inv_k_fixed,
            self.inv_es,
            self.inv_spring,
            self.l_winch,
            self.damping,
            self.opt.pulley_friction,
            self.com_pos,
            self.R,
            self.v,
            self.w,
            self.theta,
            self.theta_dot,
            self.motor_torque,
            self.brake,
            self.brake_slip,
            self.cable_cut,
            self.drum_slip,
            self.ext_force,
            self.ext_moment,
            self.tension,
            *self._scratch,
            self.gripper_of_cable,
            self.g_cable,
            self.g_mass,
            self.g_jaw0,
            self.g_axis,
            self.g_friction,
            self.opt.jaw_friction_velocity,
            self.g_travel_max,
            self.g_k_jb,
            self.g_c_jb,
            self.g_k_stop,
            self.g_c_stop,
            self.g_object_travel,
            self.g_k_contact,
            self.g_c_contact,
            self.jaw_travel,
            self.jaw_speed,
            self.jb_tension,
            self.contact_force,
        )
        self.time += duration

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
        for i in range(self.m):
            if stretch[i] > 0 and not self.cable_cut[i]:
                k = 1.0 / cable_compliance_py(
                    self.inv_k_fixed[i], self.inv_es[i], self.l_winch[i], self.inv_spring[i], l0[i]
                )
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


def equilibrium_tensions(model: RobotModel, kin: KinematicsData) -> FloatArray:
    """Tensions (N) holding the platform's weight (and the jaws', eq. (46)) at the pose of
    ``kin``: the barycenter (QP for r != 2; the minimum energy when the robot's TDA is the
    energy one); the minimum tensions when the pose cannot be held."""
    from cdprctl.gripper import GripperSet
    from cdprctl.tda import TDAMethod, TDAOptions, TensionDistributor

    method = TDAMethod.BARYCENTER if model.redundancy == 2 else TDAMethod.QP
    if model.control.tda_method == "energy":  # the robot was parked by its own distribution
        method = TDAMethod.ENERGY
    gs = GripperSet(model)
    R = kin.rotation
    load = gs.parallel_load(R)
    hold = -(model.gravity_wrench(R) + gs.weight_wrench(R))
    out = TensionDistributor(model, TDAOptions(method=method)).solve(
        kin.W, gs.spring_wrench(kin.W, hold, load), k=model.cable_stiffness(kin.length)
    )
    t = out.tensions.copy() if out.ok else model.tension_min.copy()
    t[gs.cables] += load  # jB carries the jaws
    return t


@njit(cache=True)
def _jaw_dynamics(
    dt, P, R, com_pos, v, w, F, Mc, mass, Iw, g, rbT, g_cable, g_mass, g_jaw0, g_axis,
    g_fric, g_fric_v, g_qmax, g_kstop, g_cstop, g_L21, g_kc, g_cc, q, qd, g_tb, g_fc,
):  # fmt: skip  # pragma: no cover - compiled
    """Platform and jaws together (Kane's method): generalised speeds ``u = [v_COM, ω, q̇_j]``,
    jaw velocity ``v_j = v + ω × r_j + q̇_j k_j`` (``k_j`` the guide, ``r_j`` COM → jaw), so
    ``(M_b + Σ m_j J_jᵀJ_j) u̇ = Q − Σ m_j J_jᵀ (ω×(ω×r_j) + 2 ω×q̇_j k_j)``; the guide's
    reactions do no work and drop out. Advances ``v``, ``ω``, ``q̇`` and ``q`` by ``dt``.
    ``F``/``Mc``: force and moment (about the COM, Euler term included) on the platform from
    the cables, gravity and the external wrench; jB pulls the jaw along ``k_j`` and the pulley
    at the cable's attachment along ``−k_j``; the object, the stops and the friction act
    between jaw and platform along the guide."""
    ng = g_mass.shape[0]
    n = 6 + ng
    A = np.zeros((n, n))
    Q = np.zeros(n)
    for a in range(3):
        A[a, a] = mass
        Q[a] = F[a]
        Q[3 + a] = Mc[a]
        for b in range(3):
            A[3 + a, 3 + b] = Iw[a, b]
    for j in range(ng):
        i = g_cable[j]
        k = R @ g_axis[j]
        r = P + R @ g_jaw0[j] + q[j] * k - com_pos
        mj = g_mass[j]
        # pulley at the attachment: −t_B k on the platform
        tb = g_tb[j]
        y = np.empty(3)
        for a in range(3):
            y[a] = rbT[a, i] + P[a] - com_pos[a]  # rbT: R b_i, from P
            Q[a] -= tb * k[a]
        Q[3] -= y[1] * tb * k[2] - y[2] * tb * k[1]
        Q[4] -= y[2] * tb * k[0] - y[0] * tb * k[2]
        Q[5] -= y[0] * tb * k[1] - y[1] * tb * k[0]
        # forces on the jaw: gravity and t_B along k, through J_jᵀ = [I; [r]×; kᵀ]
        f = np.empty(3)
        for a in range(3):
            f[a] = mj * g[a] + tb * k[a]
        # velocity-product acceleration c = ω×(ω×r) + 2 ω×(q̇ k), as forces −m c
        wr = np.cross(w, r)
        c = np.cross(w, wr) + 2.0 * qd[j] * np.cross(w, k)
        for a in range(3):
            f[a] -= mj * c[a]
        rf = np.cross(r, f)
        for a in range(3):
            Q[a] += f[a]
            Q[3 + a] += rf[a]
        Q[6 + j] += f[0] * k[0] + f[1] * k[1] + f[2] * k[2]
        # along the guide, between jaw and platform: object, end stops, friction
        s = 0.0
        fc = 0.0
        if q[j] > g_L21[j]:
            fc = g_kc[j] * (q[j] - g_L21[j]) + g_cc[j] * qd[j]
            if fc < 0.0:
                fc = 0.0
        s -= fc
        g_fc[j] = fc
        if q[j] < 0.0:
            st = -g_kstop[j] * q[j] - g_cstop[j] * qd[j]
            s += st if st > 0.0 else 0.0
        elif q[j] > g_qmax[j]:
            st = g_kstop[j] * (q[j] - g_qmax[j]) + g_cstop[j] * qd[j]
            s -= st if st > 0.0 else 0.0
        s -= g_fric[j] * math.tanh(qd[j] / g_fric_v)
        Q[6 + j] += s
        # mass matrix: m J_jᵀ J_j with J_j = [I, −[r]×, k e_j]
        rr = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        rk = np.cross(r, k)
        for a in range(3):
            A[a, a] += mj
            A[a, 6 + j] += mj * k[a]
            A[6 + j, a] += mj * k[a]
            A[3 + a, 6 + j] += mj * rk[a]
            A[6 + j, 3 + a] += mj * rk[a]
            for b in range(3):
                A[3 + a, 3 + b] += mj * ((rr if a == b else 0.0) - r[a] * r[b])
        # the −[r]× block and its transpose: (−[r]×)[a, b] = ε_abc r_c
        for a in range(3):
            b, c = (a + 1) % 3, (a + 2) % 3
            A[a, 3 + b] += mj * r[c]
            A[a, 3 + c] -= mj * r[b]
            A[3 + b, a] += mj * r[c]
            A[3 + c, a] -= mj * r[b]
        A[6 + j, 6 + j] += mj
    udot = np.linalg.solve(A, Q)
    for a in range(3):
        v[a] += udot[a] * dt
        w[a] += udot[3 + a] * dt
    for j in range(ng):
        qd[j] += udot[6 + j] * dt
        q[j] += qd[j] * dt


@njit(cache=True)
def physics_kernel(
    n,
    dt,
    anchors,
    attach,
    pr,
    pa,
    com,
    mass,
    inertia,
    g,
    l_home,
    drum_ratio,
    J,
    visc,
    coul,
    coul_v,
    inv_k_fixed,
    inv_es,
    inv_spring,
    l_w,
    damping,
    mu_p,
    com_pos,
    R,
    v,
    w,
    theta,
    theta_dot,
    tau_m,
    brake,
    slip,
    cut,
    drum_slip,
    f_ext,
    m_ext,
    tension,
    rbT,
    exitT,
    vT,
    free_len,
    wrap,
    length,
    W,
    g_of_cable,
    g_cable,
    g_mass,
    g_jaw0,
    g_axis,
    g_fric,
    g_fric_v,
    g_qmax,
    g_kjb,
    g_cjb,
    g_kstop,
    g_cstop,
    g_L21,
    g_kc,
    g_cc,
    q,
    qd,
    g_tb,
    g_fc,
):  # pragma: no cover - compiled
    m = anchors.shape[0]
    ng = g_mass.shape[0]
    P = np.empty(3)
    twist = np.empty(6)
    for _ in range(n):
        Rc = R @ com
        for a in range(3):
            P[a] = com_pos[a] - Rc[a]
        ik_kernel(anchors, attach, pr, pa, P, R, rbT, exitT, vT, free_len, wrap, length, W)
        # twist at P: v_P = v_com + ω × (P − COM) = v_com − ω × Rc
        twist[0] = v[0] - (w[1] * Rc[2] - w[2] * Rc[1])
        twist[1] = v[1] - (w[2] * Rc[0] - w[0] * Rc[2])
        twist[2] = v[2] - (w[0] * Rc[1] - w[1] * Rc[0])
        twist[3], twist[4], twist[5] = w[0], w[1], w[2]
        F = np.zeros(3)
        M = np.zeros(3)  # about the COM
        for i in range(m):
            l0 = l_home[i] - drum_ratio[i] * theta[i] + drum_slip[i]
            e = length[i] - l0
            t = 0.0
            if e > 0.0 and not cut[i]:
                k = 1.0 / cable_compliance(inv_k_fixed[i], inv_es[i], l_w[i], inv_spring[i], l0)
                ldot = 0.0
                for a in range(6):
                    ldot -= W[a, i] * twist[a]  # dl/dt = −Wᵀ twist
                edot = ldot + drum_ratio[i] * theta_dot[i]
                t = k * e + damping[i] * edot
                if t < 0.0:
                    t = 0.0
                j = g_of_cable[i]
                if j >= 0:  # the cable splits: jA (the spring, t) and jB to the jaw
                    tb = g_kjb[j] * (e - q[j]) + g_cjb[j] * (edot - qd[j])
                    g_tb[j] = tb if tb > 0.0 else 0.0
                    t += g_tb[j]
            elif g_of_cable[i] >= 0:
                g_tb[g_of_cable[i]] = 0.0
            tension[i] = t
            if t > 0.0:
                fx, fy, fz = t * W[0, i], t * W[1, i], t * W[2, i]
                F[0] += fx
                F[1] += fy
                F[2] += fz
                # moment about the COM: (R b_i − R c) × f
                rx, ry, rz = rbT[0, i] - Rc[0], rbT[1, i] - Rc[1], rbT[2, i] - Rc[2]
                M[0] += ry * fz - rz * fy
                M[1] += rz * fx - rx * fz
                M[2] += rx * fy - ry * fx
            # winch: J θ̈ = τ_m − (r/G) t_w − b θ̇ − τ_c tanh(θ̇/ω_ε)
            if brake[i]:
                theta_dot[i] = -slip[i]  # a slipping brake pays cable out
                theta[i] += theta_dot[i] * dt
            else:
                cap = 1.0
                if mu_p > 0.0 and wrap[i] > 0.0:
                    cap = math.exp(mu_p * wrap[i] * math.tanh(theta_dot[i] / coul_v))
                acc = (
                    tau_m[i]
                    - drum_ratio[i] * t * cap
                    - visc[i] * theta_dot[i]
                    - coul[i] * math.tanh(theta_dot[i] / coul_v)
                ) / J[i]
                theta_dot[i] += acc * dt
                theta[i] += theta_dot[i] * dt
        # external wrench at P: moment about the COM adds (P − COM) × f = −Rc × f
        for a in range(3):
            F[a] += mass * g[a] + f_ext[a]
            M[a] += m_ext[a]
        M[0] += -(Rc[1] * f_ext[2] - Rc[2] * f_ext[1])
        M[1] += -(Rc[2] * f_ext[0] - Rc[0] * f_ext[2])
        M[2] += -(Rc[0] * f_ext[1] - Rc[1] * f_ext[0])
        # Newton-Euler at the COM, world frame: I_w ω̇ = M − ω × I_w ω
        Iw = R @ inertia @ R.T
        Iww = Iw @ w
        rhs = np.empty(3)
        rhs[0] = M[0] - (w[1] * Iww[2] - w[2] * Iww[1])
        rhs[1] = M[1] - (w[2] * Iww[0] - w[0] * Iww[2])
        rhs[2] = M[2] - (w[0] * Iww[1] - w[1] * Iww[0])
        if ng == 0:
            wdot = np.linalg.solve(Iw, rhs)
            for a in range(3):
                v[a] += F[a] / mass * dt
                w[a] += wdot[a] * dt
        else:
            _jaw_dynamics(
                dt, P, R, com_pos, v, w, F, rhs, mass, Iw, g, rbT, g_cable, g_mass,
                g_jaw0, g_axis, g_fric, g_fric_v, g_qmax, g_kstop, g_cstop, g_L21, g_kc, g_cc,
                q, qd, g_tb, g_fc,
            )  # fmt: skip
        for a in range(3):
            com_pos[a] += v[a] * dt
        # R ← exp([ω dt]×) R
        E = np.empty((3, 3))
        exp_so3_kernel(w[0] * dt, w[1] * dt, w[2] * dt, E)
        R[:, :] = E @ R
