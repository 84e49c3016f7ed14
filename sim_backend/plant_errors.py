"""Geometric errors of the simulated robot against its config: the plant built from a robot
whose anchors (exit points, or swivel-axis points with pulleys) are offset and whose drum
radii are scaled, seeded, so that a calibration is tested against a robot that is not its own
model (docs/homing.md)."""

from __future__ import annotations

import dataclasses

import numpy as np

from cdprctl.model.robot import RobotModel


@dataclasses.dataclass(frozen=True)
class PlantErrors:
    """Each anchor offset by up to ``anchor`` (m) per axis and each drum radius scaled by up
    to ``drum`` (fraction), uniformly at random from ``seed``."""

    seed: int
    anchor: float = 0.005  # m
    drum: float = 0.005  # fraction of the radius
    exact: tuple[int, ...] = ()  # anchors kept as drawn (a calibration's reference anchors)

    def apply(self, model: RobotModel) -> tuple[RobotModel, dict[str, list[float]]]:
        """The robot the plant simulates, and the errors drawn: ``anchor_offsets`` (m, base
        frame, per cable) and ``drum_scales`` (per cable)."""
        rng = np.random.default_rng(self.seed)
        m = model.n_cables
        offsets = rng.uniform(-self.anchor, self.anchor, (m, 3))
        offsets[list(self.exact)] = 0.0
        scales = 1.0 + rng.uniform(-self.drum, self.drum, m)
        cables = []
        for i, c in enumerate(model.cables):
            winch = dataclasses.replace(c.winch, drum_radius=c.winch.drum_radius * scales[i])
            cables.append(
                dataclasses.replace(
                    c, anchor=np.asarray(c.anchor) + offsets[i], winch=winch
                )
            )
        errors = {"anchor_offsets": offsets.tolist(), "drum_scales": scales.tolist()}
        return dataclasses.replace(model, cables=tuple(cables)), errors
