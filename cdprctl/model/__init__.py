"""Robot description: the frozen dataclasses and the readers of their sections (the
loader, which checks a robot with the geometry, is cdprctl.robot_file)."""

from cdprctl.model.errors import ConfigError
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
]
