"""The ``cdprctl`` command line."""

from __future__ import annotations

import argparse
import re
import signal
import sys
from collections.abc import Sequence
from typing import Any

from cdprctl import __version__


def _cmd_check_config(args: argparse.Namespace) -> int:
    from cdprctl.commands.check_config import run

    return run(args.file, strict=args.strict)


def _add_check_config(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check-config",
        help="validate a robot description and print its summary",
        description="Validate a robot description (TOML). Prints a summary (cables, limits, "
        "mass, cable lengths at the home pose) or every error found; exit code 1 on error. "
        "A limit the file's geometry breaks (the cables under the clearance at home or in the "
        "workspace box) is a warning: the first line says 'valid, with N warnings' instead of "
        "OK, each warning under it; exit code 0 (cdprctl run accepts the file), 1 with --strict.",
    )
    p.add_argument("file", help="robot description, e.g. config/seed000.toml")
    p.add_argument(
        "--strict",
        action="store_true",
        help="exit code 1 on a warning too (for CI: a file that must be clean)",
    )
    p.set_defaults(func=_cmd_check_config)


#: the tools that talk to robots over Zenoh and import neither numpy nor the robot model: run
#: alone, only their parsers are built (the others' imports took a second of each ``send``)
LIGHT = {"send": "zenoh_tools", "monitor": "zenoh_tools", "robots": "fleet",
         "zenoh-router": "fleet", "jog": "jog", "record": "record"}  # fmt: skip


def _light_parser(command: str) -> argparse.ArgumentParser:
    import importlib

    parser, sub = _top_parser()
    module = importlib.import_module(f"cdprctl.commands.{LIGHT[command]}")
    (getattr(module, "add_parsers", None) or module.add_parser)(sub)
    return parser


class Parser(argparse.ArgumentParser):
    """argparse taking a value that starts like a negative number as a value: ``--grid
    -1.5:1.5:20,...``, ``--pose -0.5,0,1``, ``--wrench -30,0,0,0,0,0`` (argparse takes only
    ``-1.5`` alone so, and stopped the others on "expected one argument"). No option of
    cdprctl starts with a digit. Subcommands' parsers are of this class too."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")


def _top_parser() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction]:
    parser = Parser(
        prog="cdprctl",
        description="Controller and tools for cable-driven parallel robots (SI units throughout).",
    )
    parser.add_argument("--version", action="version", version=f"cdprctl {__version__}")
    return parser, parser.add_subparsers(dest="command", metavar="COMMAND")


def build_parser() -> argparse.ArgumentParser:
    parser, sub = _top_parser()
    _add_check_config(sub)
    from cdprctl.commands import bus_load, calibrate, demo, sim
    from cdprctl.commands import run as run_cmd
    from cdprctl.commands import tda as tda_cmd

    demo.add_parser(sub)
    run_cmd.add_parser(sub)
    sim.add_parser(sub)
    calibrate.add_parser(sub)
    from cdprctl.commands import brake_test

    brake_test.add_parser(sub)
    from cdprctl.commands import load_cells

    load_cells.add_parser(sub)
    tda_cmd.add_parser(sub)
    bus_load.add_parser(sub)
    from cdprctl.commands import drives

    drives.add_parser(sub)
    from cdprctl.commands import record, report, zenoh_tools
    from cdprctl.commands import workspace as workspace_cmd

    zenoh_tools.add_parsers(sub)
    record.add_parser(sub)
    report.add_parser(sub)
    workspace_cmd.add_parser(sub)
    from cdprctl.commands import fleet, jog, path

    fleet.add_parsers(sub)
    jog.add_parser(sub)
    path.add_parser(sub)
    return parser


def _stop(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _list_options(parser: argparse.ArgumentParser) -> set[str]:
    """The options, in every sub-command, whose value is a comma-separated list of numbers
    (their metavar says so: ``X,Y,Z``)."""
    found: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= _list_options(sub)
        elif isinstance(action.metavar, str) and "," in action.metavar:
            found.update(action.option_strings)
    return found


def signed_lists_attached(parser: argparse.ArgumentParser, words: list[str]) -> list[str]:
    """``--start-pose -0.02,0.01,...`` as ``--start-pose=-0.02,0.01,...``: argparse takes a
    value that starts with '-' and is not a plain number for an option and refuses it
    ("expected one argument"), though a pose left of the origin is an ordinary one."""
    lists = _list_options(parser)
    out: list[str] = []
    for word in words:
        if out and out[-1] in lists and re.match(r"-\.?\d", word):
            out[-1] = f"{out[-1]}={word}"
        else:
            out.append(word)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    previous = signal.signal(signal.SIGTERM, _stop)  # as Ctrl-C, from the first moment
    try:
        light = bool(words) and words[0] in LIGHT
        parser = _light_parser(words[0]) if light else build_parser()
        args = parser.parse_args(signed_lists_attached(parser, words))
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        return int(args.func(args))
    except KeyboardInterrupt as exc:  # before a command's own handling, or a tool's Ctrl-C
        name = str(exc) or "SIGINT"
        if words[:1] == ["run"]:  # a stop during the start-up (docs/operating.md)
            from cdprctl.daemon.startup import StartupInterrupted

            stop = exc if isinstance(exc, StartupInterrupted) else StartupInterrupted(name)
            print(stop.message, file=sys.stderr)
            return stop.code
        print(f"cdprctl: interrupted ({name})", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`| head`): no traceback, nothing more
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # for the exit's flush
        return 141  # 128 + SIGPIPE, as a shell reports it
    finally:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
