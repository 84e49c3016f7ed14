"""A sub-command's parser: argparse only, so the Zenoh tools that use nothing else (``send``,
``monitor``, ``robots``, ``jog``) start without importing numpy or the robot model."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any


def command_parser(
    sub: Any,
    name: str,
    help: str,
    func: Callable[[argparse.Namespace], int],
    config: bool = True,
    description: str | None = None,
    epilog: str | None = None,
) -> argparse.ArgumentParser:
    """The parser of sub-command ``name``, run by ``func``, described by ``func``'s docstring
    (or ``description``); with ``config`` its ``--config FILE`` (the robot description). An
    ``epilog`` (examples) is printed as written, and so is the description then."""
    extra: dict[str, Any] = {}
    if epilog is not None:
        extra = {"epilog": epilog, "formatter_class": argparse.RawDescriptionHelpFormatter}
    p: argparse.ArgumentParser = sub.add_parser(
        name, help=help, description=description or func.__doc__, **extra
    )
    if config:
        p.add_argument("--config", required=True, help="robot description (TOML)")
    p.set_defaults(func=func, cmd=name)
    return p
