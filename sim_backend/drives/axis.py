"""The CiA 402 axis of a simulated drive: the power state machine, the modes of operation and
the power stage acting on its winch of the plant.

The power state machine is CiA 402's (the transition table of ``drivers.cia402.protocol``,
driven by the controlword); the power stage applies the torque (mode 10, cyclic synchronous
torque) or runs the drive's own position loop towards a target interpolated linearly between
SYNCs (mode 8, ``servo.Servo``), within the torque limit, and closes the brake whenever the
axis is not enabled. The encoder is the motor's angle in counts (32-bit, with its faults: a
jump, an incremental counter restarting at zero). What the axis is told comes from its node
(``cia402.Cia402Drive``: the CiA 301 side), and what it reads of the object dictionary it
reads from the node's values (the mode 0x6060, the torque limit 0x6072, 0x6065/0x6066).
"""

from __future__ import annotations

import math
from typing import Any

from drivers.cia402 import protocol as p
from drivers.cia402.brake import (
    OD_DIGITAL_OUTPUTS,
    SUB_BIT_MASK,
    SUB_PHYSICAL_OUTPUTS,
    brake_commanded,
)
from sim_backend.plant import CdprPlant
from sim_backend.servo import following_error_py

# maxon EPOS4's "STO input states" (0x3202:01; its EDS): both inputs energised
OD_STO_INPUTS = 0x3202
STO_INPUTS_CLOSED = 0x03

# the states with the power stage on: where an open safety chain faults the drive
ENERGISED = frozenset((p.PowerState.SWITCHED_ON, p.PowerState.OPERATION_ENABLED,
                       p.PowerState.QUICK_STOP_ACTIVE))  # fmt: skip


class Cia402Axis:
    def __init__(self, cable: int, plant: CdprPlant, od: dict[tuple[int, int], Any],
                 rated_torque: float, counts_per_rev: int, torque_limit: float,
                 position_gains: tuple[float, float], extrapolate_for: float):  # fmt: skip
        """``od``: the node's object values, (index, sub) → value; ``rated_torque`` N·m per
        1000 per-mille; ``torque_limit`` N·m (the winch's); ``position_gains`` (N·m/rad,
        N·m·s/rad) the position loop's in mode 8; ``extrapolate_for`` s: how long a target
        goes on at its last rate without a new one before the axis holds it."""
        self.cable = cable
        self.plant = plant
        self.od = od
        self.rated_torque = rated_torque
        self.cpr = counts_per_rev
        self.torque_limit = torque_limit
        self.position_gains = position_gains
        self.extrapolate_for = extrapolate_for
        self.state = p.PowerState.SWITCH_ON_DISABLED  # transitions 0 and 1 done at power-on
        self.last_controlword = 0
        self.fault_code = 0
        self.torque_pm = 0  # applied: the target torque (mode 10), the offset (mode 8)
        self.target_counts: int | None = None  # mode 8: the last target position
        self.last_target = -math.inf  # s, the SYNC that applied the last RPDO
        self.encoder_offset = 0  # counts, fault injection: an encoder jump
        # incremental encoder: the counter restarts at zero at power-up and at a reset node;
        # ``encoder_zero`` is the motor angle (counts) it restarted at. Absolute: kept (0)
        self.incremental = False
        self.encoder_zero = 0
        # the safety chain at the drive's STO input: open, the power stage can give no torque
        # (``open_sto``); ``sto_code`` the error it reports, ``emcy_due`` one its node sends
        self.sto_open = False
        self.sto_code = p.EMCY_STO
        # s: when the brake, released by an opening chain, has closed (inf: not closing);
        # meanwhile the drum turns freely (``PlantOptions.brake_close_time``)
        self.brake_due = math.inf
        self.emcy_due: int | None = None

    # -- the device profile ------------------------------------------------------------------
    @property
    def mode(self) -> int:
        return self.od[(p.OD_MODES_OF_OPERATION, 0)]

    def supports_mode(self, mode: int) -> bool:
        """0x6502: bit 7 cyclic synchronous position, bit 9 torque (CiA 402 §6.4.7)."""
        bit = p.SUPPORTED_MODE_BIT.get(mode)
        return bit is not None and bool(self.od[(p.OD_SUPPORTED_DRIVE_MODES, 0)] >> bit & 1)

    def apply_controlword(self, cw: int) -> None:
        """The controlword's command through the transition table (fault reset on the
        rising edge of bit 7)."""
        cmd = p.command_of(cw)
        rising_reset = bool(cw & 0x80) and not bool(self.last_controlword & 0x80)
        self.last_controlword = cw
        if cmd is p.Command.FAULT_RESET and not rising_reset:
            return
        if cmd is p.Command.FAULT_RESET and self.sto_open:
            return  # the error persists while the chain is open: the reset is refused
        if cmd is p.Command.FAULT_RESET and self.state is p.PowerState.FAULT:
            self.fault_code = 0
        if cmd is None:
            return
        nxt = p.TRANSITIONS.get((self.state, cmd))
        if nxt is not None and self.sto_open and nxt[0] in ENERGISED:
            self.fault(self.sto_code)  # switching the power stage on with the chain open
            self.emcy_due = self.sto_code
        elif nxt is not None:
            if self.state is p.PowerState.READY_TO_SWITCH_ON and cmd is p.Command.ENABLE_OPERATION:
                self.state = p.PowerState.OPERATION_ENABLED  # 3 then 4 in one step
            else:
                self.state = nxt[0]

    def take(self, t: float, torque: int | None, position: int | None, offset: int | None) -> bool:
        """The targets of the RPDO a SYNC at ``t`` (s) applies (None: not mapped); True when a
        new position target came (mode 8)."""
        self.last_target = t
        if self.mode == p.MODE_CSP:
            if position is not None:
                self.target_counts = position
            self.torque_pm = offset if offset is not None else 0
            return position is not None
        if torque is not None:
            self.torque_pm = torque
        return False

    def fault(self, code: int) -> None:
        """A drive fault: FAULT state (transition 13), the code, the brake."""
        self.state = p.PowerState.FAULT
        self.fault_code = code
        self.apply()

    def open_sto(self, code: int, t: float | None = None) -> bool:
        """The safety chain opens (an e-stop) at ``t`` (s): no torque from now on, and a
        released brake closes ``brake_close_time`` later (at once without ``t``): the drum
        turns freely meanwhile; an energised power stage (switched on, enabled, quick stop)
        faults with ``code``, as a maxon EPOS4 does (0x8A88; docs/safety.md), and True (its
        node sends the EMCY); a disabled one stays disabled, no error, until it is switched
        on."""
        self.sto_open, self.sto_code = True, code
        if self.state in ENERGISED or self.state is p.PowerState.FAULT_REACTION_ACTIVE:
            released = not self.plant.brake[self.cable]
            close = self.plant.opt.brake_close_time
            if released and t is not None and close > 0.0:
                self.brake_due = t + close
            self.fault(code)
            return True
        return False

    def sto_inputs(self) -> int:
        """maxon EPOS4's 0x3202:01 "STO input states", as the simulated drives read it: bits
        0 and 1 the two STO inputs, set while energised (the chain closed: torque allowed)."""
        return 0 if self.sto_open else STO_INPUTS_CLOSED

    def close_sto(self) -> None:
        """The chain closes: the error stays until a fault reset (the operator's
        acknowledgement), then the drive can be enabled again."""
        self.sto_open = False

    def connection_lost(self, option: int) -> None:
        """The abort-connection option code's reaction (0x6007, CiA 402 §6.4.1; not 0): 2
        disable voltage, 3 quick stop, 1 and the manufacturer-specific codes the fault
        reaction (EMCY 0x8130's code)."""
        if option == 2:
            self.state = p.PowerState.SWITCH_ON_DISABLED  # transition 9
        elif option == p.ABORT_CONNECTION_QUICK_STOP:
            self.state = p.PowerState.QUICK_STOP_ACTIVE  # transition 11
        else:
            self.state = p.PowerState.FAULT  # transition 13
            self.fault_code = 0x8130
        self.apply()

    def reset(self) -> None:
        """A reset node: the state machine restarted, the brake, an incremental counter at
        zero."""
        self.state = p.PowerState.SWITCH_ON_DISABLED
        self.fault_code = 0
        self.brake_due = math.inf
        self.apply()
        if self.incremental:
            self.zero_counter()

    # -- the power stage on the plant ----------------------------------------------------------
    @property
    def effective_torque_limit(self) -> float:
        """N·m: the winch's limit, or 0x6072 (per mille of the rated torque) if lower."""
        max_torque = self.od[(p.OD_MAX_TORQUE, 0)] * self.rated_torque / 1000.0
        return min(self.torque_limit, max_torque)

    def torque_actual_pm(self) -> int:
        """0x6077 (per mille of rated): the torque the drive applies, after its limit."""
        if self.state is not p.PowerState.OPERATION_ENABLED:
            return 0
        c = self.cable
        # in position mode, what its loop applies now
        csp = self.mode == p.MODE_CSP
        tau = self.plant.servo.applied[c] if csp else self.plant.motor_torque[c]
        return max(-32767, min(32767, round(tau * 1000.0 / self.rated_torque)))

    def set_following_error(self) -> None:
        """The position loop's following-error window (rad) and time-out (s) from 0x6065 and
        0x6066: set when they are written, not at every SYNC."""
        window = self.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] & 0xFFFFFFFF
        servo, c = self.plant.servo, self.cable
        off = window == p.FOLLOWING_ERROR_OFF
        servo.window[c] = math.inf if off else window * 2.0 * math.pi / self.cpr
        servo.timeout[c] = self.od[(p.OD_FOLLOWING_ERROR_TIMEOUT, 0)] / 1000.0

    def apply(self, interval: float = math.inf, fresh: bool = True, period: float = 0.0) -> None:
        """The state and targets onto the plant. ``interval`` (s): since the last SYNC;
        ``fresh``: a new target came with this SYNC (without one, position mode goes on at the
        target's last rate, as across a late SYNC: stopping the target for a period and
        catching up after made a following error of a period's travel at every lost frame);
        ``period`` (s): the SYNC period as the node sees it."""
        c, servo, plant = self.cable, self.plant.servo, self.plant
        if self.state is p.PowerState.OPERATION_ENABLED:
            tau = self.torque_pm * self.rated_torque / 1000.0
            limit = self.effective_torque_limit
            tau = max(-limit, min(limit, tau))
            plant.motor_torque[c] = tau
            servo.limit[c] = limit
            if self.mode == p.MODE_CSP:
                theta = plant.theta[c]
                if servo.kp[c] <= 0.0:  # just enabled: the loop starts where the motor is
                    servo.target[c] = theta
                    servo.rate[c] = 0.0
                if self.target_counts is not None and fresh:
                    now = self.counts()
                    step = ((self.target_counts - now + 0x80000000) & 0xFFFFFFFF) - 0x80000000
                    end = theta + step * 2.0 * math.pi / self.cpr
                    # reach it one SYNC period from now (the drive's estimate of the period);
                    # after a long gap, a step
                    if 0.0 <= interval < self.extrapolate_for and period > 0.0:
                        servo.rate[c] = (end - servo.target[c]) / period
                    else:
                        servo.target[c], servo.rate[c] = end, 0.0
                servo.kp[c], servo.kd[c] = self.position_gains
            else:
                servo.kp[c] = 0.0
            if self.brake_set():  # a brake test: enabled, pushing against the closed brake
                plant.close_brake(c)
            else:
                plant.brake[c] = False
        else:  # disabled, quick stop, fault: no torque, the brake holds the drum
            plant.motor_torque[c] = 0.0
            servo.kp[c] = 0.0
            servo.beyond[c] = 0.0
            self.target_counts = None
            if self.brake_due == math.inf:
                plant.close_brake(c)
            else:  # cut by the safety chain: closing, the drum free until ``brake_due``
                plant.brake[c] = False

    def brake_set(self) -> bool:
        """Whether the master closed the brake (0x60FE bit 0 "set brake", enabled by its
        mask): it stays closed while the drive is enabled."""
        od = self.od
        return brake_commanded(
            od.get((OD_DIGITAL_OUTPUTS, SUB_PHYSICAL_OUTPUTS), 0),
            od.get((OD_DIGITAL_OUTPUTS, SUB_BIT_MASK)),
        )

    def holds_at(self) -> float:
        """s: the next instant the axis changes by itself: the position target stops going
        on at its last rate, ``extrapolate_for`` after the last new one, or a closing brake
        closes (inf: neither)."""
        moving = self.plant.servo.rate[self.cable] != 0.0
        stops = self.last_target + self.extrapolate_for if moving else math.inf
        return min(stops, self.brake_due)

    def hold_if_due(self, t: float) -> None:
        """At ``t`` (s): the position target held once it is due, a closing brake closed."""
        moving = self.plant.servo.rate[self.cable] != 0.0
        if moving and t >= self.last_target + self.extrapolate_for:
            self.plant.servo.rate[self.cable] = 0.0
        if t >= self.brake_due:
            self.brake_due = math.inf
            self.plant.close_brake(self.cable)

    def following_error(self) -> bool:
        """Whether the position loop's following error has been beyond its window for longer
        than its time-out, while enabled (the drive faults: EMCY 0x8611)."""
        enabled = self.state is p.PowerState.OPERATION_ENABLED
        return enabled and following_error_py(self.plant.servo, self.cable)

    # -- the encoder -----------------------------------------------------------------------------
    def counts(self) -> int:
        """Position actual (counts, 32-bit): the encoder from its zero, with an injected
        jump."""
        counts = round(self.plant.theta[self.cable] * self.cpr / (2.0 * math.pi))
        counts += self.encoder_offset - self.encoder_zero
        return ((counts + 0x80000000) & 0xFFFFFFFF) - 0x80000000

    def velocity_counts(self) -> int:
        """Velocity actual (counts/s)."""
        return round(self.plant.theta_dot[self.cable] * self.cpr / (2.0 * math.pi))

    def jump_encoder(self, counts: int) -> None:
        """Fault injection: the encoder jumps by ``counts``. In position mode the drive's loop
        sees it at once: its target, in the true motor angle, moves the other way."""
        self.encoder_offset += counts
        if self.state is p.PowerState.OPERATION_ENABLED and self.mode == p.MODE_CSP:
            self.plant.servo.target[self.cable] -= counts * 2.0 * math.pi / self.cpr

    def zero_counter(self) -> None:
        """An incremental encoder's counter restarting (power-up, reset node): it reads zero
        wherever the motor stands."""
        self.encoder_zero = round(self.plant.theta[self.cable] * self.cpr / (2.0 * math.pi))
