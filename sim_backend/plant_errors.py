"""Errors of the simulated robot against its config: the plant built from a robot whose
anchors (exit points, or swivel-axis points with pulleys) are offset, whose drum radii are
scaled and whose winches' friction differs from the file's, each its own, seeded, so that a
calibration is tested against a robot that is not its own model (docs/homing.md,
docs/friction.md)."""

from __future__ import annotations

import dataclasses

import numpy as np

from cdprctl.model.robot import RobotModel


@dataclasses.dataclass(frozen=True)
class PlantErrors:
    """Each anchor offset by up to ``anchor`` (m) per axis and each drum radius scaled by up
    to ``drum`` (fraction), uniformly at random from ``seed``; each winch's viscous and
    Coulomb friction off the file's by a fraction drawn in ``friction`` (low, high), up or
    down at random, its Stribeck term ``stribeck`` times its Coulomb one (where the file has
    none) and every pulley's μ ``pulley`` (drawn after the geometry: a seed's anchors and
    drums are the same with or without them)."""

    seed: int
    anchor: float = 0.005  # m
    drum: float = 0.005  # fraction of the radius
    exact: tuple[int, ...] = ()  # anchors kept as drawn (a calibration's reference anchors)
    friction: tuple[float, float] = (0.0, 0.0)  # fraction of the file's
    stribeck: float = 0.0  # of the Coulomb term
    pulley: float | None = None  # μ of every pulley; None: the file's

    def apply(self, model: RobotModel) -> tuple[RobotModel, dict[str, list[float]]]:
        """The robot the plant simulates, and the errors drawn: ``anchor_offsets`` (m, base
        frame, per cable) and ``drum_scales`` (per cable)."""
        rng = np.random.default_rng(self.seed)
        m = model.n_cables
        offsets = rng.uniform(-self.anchor, self.anchor, (m, 3))
        offsets[list(self.exact)] = 0.0
        scales = 1.0 + rng.uniform(-self.drum, self.drum, m)
        lo, hi = self.friction
        off = rng.uniform(lo, hi, (m, 2)) * rng.choice([-1.0, 1.0], (m, 2))
        cables = []
        for i, c in enumerate(model.cables):
            w = c.winch
            coulomb = w.coulomb_friction * (1.0 + off[i, 1])
            winch = dataclasses.replace(
                w, drum_radius=w.drum_radius * scales[i],
                viscous_friction=w.viscous_friction * (1.0 + off[i, 0]),
                coulomb_friction=coulomb,
                stribeck_friction=w.stribeck_friction or self.stribeck * coulomb,
                pulley_friction=w.pulley_friction if self.pulley is None else self.pulley,
            )  # fmt: skip
            cables.append(
                dataclasses.replace(
                    c, anchor=np.asarray(c.anchor) + offsets[i], winch=winch
                )
            )
        errors = {"anchor_offsets": offsets.tolist(), "drum_scales": scales.tolist(),
                  "friction_scales": (1.0 + off).tolist()}  # fmt: skip
        return dataclasses.replace(model, cables=tuple(cables)), errors
