"""What the commands share."""

from __future__ import annotations

import sys

from cdprctl.model import ConfigError, RobotModel, load_robot


def load_or_report(path: str) -> RobotModel | None:
    """The robot of ``path``, or None after printing every error of the file to stderr."""
    try:
        return load_robot(path)
    except ConfigError as exc:
        for e in exc.errors:
            print(e, file=sys.stderr)
        return None
