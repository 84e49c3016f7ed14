"""Errors of the robot description."""

from __future__ import annotations


class ConfigError(Exception):
    """A configuration file is invalid. ``errors`` lists every problem found, one per line.

    Each message names the file, the key, the value with its unit, and the rule it breaks, e.g.
    ``config/rowc.toml: cables[3].tension_min = 250 N exceeds tension_max = 200 N``.
    """

    def __init__(self, errors: list[str]):
        self.errors = list(errors)
        super().__init__("\n".join(self.errors))
