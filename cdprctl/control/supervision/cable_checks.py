"""The supervisor's check of the cables' lengths in position mode (``FaultKind.CABLE_TENSION``):
the measured tensions pulling against each other beyond what was commanded — a cable longer
or shorter than its encoder says — and which cable may be the one. Plain arithmetic on the
cycle's arrays; text only on the fault path."""

from __future__ import annotations

import numpy as np

from cdprctl.control.supervision.persistence import Persistence
from cdprctl.core.numerics import worst_ratio
from cdprctl.model.control import ControlConfig


class TensionDisagreement:
    # The internal tension error must stay over its limit this long (position mode): the
    # measurement is already low-passed at 5 Hz; this only keeps a single bad frame out
    TENSION_FOR = 0.05  # s
    #: a cable is named when its error explains the internal part at least this well (of the
    #: best): rowc's slips and snaps put the struck cable within 0.4 % of the best and the
    #: cables of the other group below 30 % (lock-step, measured)
    SUSPECT_SHARE = 0.9

    def __init__(self, config: ControlConfig, limits: np.ndarray | None):
        """``limits`` (N, per cable): the internal tension error that faults."""
        self.config, self.limits = config, limits
        self.over = Persistence(self.TENSION_FOR)  # inverse-time: the weight is the ratio

    def check(self, t: float, err: np.ndarray, leverage: np.ndarray, at_limit: bool) -> str | None:
        """Why a cable is not the length its encoder says, once its internal tension error
        (``err``, N) has been beyond its limit for ``TENSION_FOR``; None otherwise. A drive at
        its torque limit (``at_limit``) does not apply its commanded tension: the disagreement
        says nothing of a cable's length then, and the beyond-capacity check owns the case
        (400 N on rowc, the reference's tensions on a platform pushed off it: the tension
        check blamed cable 5 before the drives had been at their limit 30 ms)."""
        lim = self.limits
        assert lim is not None
        i = worst_ratio(err, lim)
        e = err.item(i)  # item: plain floats (a numpy scalar was a block each cycle)
        ratio = abs(e) / lim.item(i)
        if not self.over.held(t, ratio > 1.0 and not at_limit, ratio):
            return None
        limit = self.config.max_tension_disagreement
        suspects = self.suspects(err, leverage)
        who = ", ".join(str(j) for j in suspects[:-1]) + (" or " if len(suspects) > 1 else "")
        who += str(suspects[-1])
        alike = (
            f"; each of cables {who} alone would explain it: the null space the redundant "
            "cables leave cannot tell them apart"
            if len(suspects) > 1
            else ""
        )
        return (
            f"a cable is not the length its encoder says, index {who}: the cables pull against "
            f"each other beyond what was commanded, {e:+.1f} N at index {i} (> {lim[i]:.1f} N = "
            f"max_tension_disagreement {limit:g} of its range, for "
            f"{self.TENSION_FOR * 1e3:.0f} ms{alike}; an encoder jump, a slipped or broken cable)"
        )

    @classmethod
    def suspects(cls, internal: np.ndarray, leverage: np.ndarray) -> list[int]:
        """Cable indices whose own tension error alone best explains the ``internal`` part
        (N): an error ``a`` on cable j shows as ``a·p_j`` (``p_j`` the projector's column,
        ``|p_j|² = leverage[j]``), fitting best where ``|internal[j]| / √leverage[j]`` is
        largest; those within ``SUSPECT_SHARE`` of the best, best first (on the fault path
        only)."""
        score = np.abs(internal) / np.sqrt(np.maximum(leverage, 1e-12))
        order = np.argsort(-score)
        return [int(j) for j in order if score[j] >= cls.SUSPECT_SHARE * score[order[0]]]
