"""``cdprctl calibrate friction`` in lock-step on a simulated robot whose winches are not the
file's (``sim_backend.plant_errors``): what the tests, ``tools/friction_table.py`` and
``tools/friction_jet.py`` compare the identified terms with."""

from __future__ import annotations

import numpy as np

from cdprctl.calibration.friction_procedure import (
    FrictionCalibration,
    FrictionOptions,
    friction_calibrate,
)
from cdprctl.model.robot import RobotModel
from sim_backend.network import LockStep
from sim_backend.plant import CdprPlant


def friction_on_plant(model: RobotModel, truth: RobotModel,
                      opt: FrictionOptions | None = None) -> FrictionCalibration:
    """The friction calibration (``opt``: its options, the command's by default) of the
    controller's ``model`` on a plant built from ``truth`` (its winches' friction, hidden
    from the controller), at rest at home, drives configured; quiet (no log). Raises what the
    procedure raises when it stops."""
    plant = CdprPlant(truth)
    plant.set_pose(model.home.position, model.home.rotation, None)
    with LockStep(model, plant=plant) as ls:
        ls.driver.configure()
        start = np.r_[model.home.position, 0.0, 0.0, 0.0]
        return friction_calibrate(model, ls.driver, np.zeros(model.n_cables), start, opt,
                                  log=lambda s: None)  # fmt: skip
