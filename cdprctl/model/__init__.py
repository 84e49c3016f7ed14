"""Robot description: frozen dataclasses and the validating TOML loader."""

from cdprctl.model.errors import ConfigError
from cdprctl.model.loader import load_robot, parse_robot
from cdprctl.model.robot import Cable, Platform, Pose, Pulley, RobotModel, Winch, Workspace

__all__ = [
    "Cable",
    "ConfigError",
    "Platform",
    "Pose",
    "Pulley",
    "RobotModel",
    "Winch",
    "Workspace",
    "load_robot",
    "parse_robot",
]
