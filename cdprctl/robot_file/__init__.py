"""A robot file (TOML) read, validated and checked with the geometry into a frozen RobotModel."""

from cdprctl.robot_file.loader import load_robot, parse_robot

__all__ = ["load_robot", "parse_robot"]
