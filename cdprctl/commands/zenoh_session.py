"""What the Zenoh tools (``send``, ``monitor``, ``record``, ``jog``) share: their options, the
robot's key prefix, the session, and the robot's status."""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any


def add_zenoh_arguments(p: argparse.ArgumentParser, robot: bool = True) -> None:
    g = p.add_argument_group("Zenoh")
    if robot:
        g.add_argument("--robot", default="", help="robot name: key prefix cdpr/NAME")
        g.add_argument("--prefix", default="", help="key prefix (instead of --robot)")
    g.add_argument("--connect", action="append", metavar="ENDPOINT", help="e.g. tcp/host:7447")
    g.add_argument("--listen", action="append", metavar="ENDPOINT")
    g.add_argument(
        "--zenoh-config", default="", metavar="FILE", help="Zenoh JSON5 (TLS, user/password)"
    )
    g.add_argument("--no-multicast-scouting", action="store_true")


def key_prefix(args: argparse.Namespace) -> str | None:
    if args.prefix:
        return str(args.prefix).rstrip("/")
    if args.robot:
        return f"cdpr/{args.robot}"
    print(f"cdprctl {args.cmd}: error: give --robot NAME or --prefix KEY", file=sys.stderr)
    return None


def tool_session(args: argparse.Namespace) -> Any:
    """The tool's Zenoh session; None, with what is wrong said in a line or a few, when the
    configuration names files that are missing or Zenoh cannot open a session."""
    from cdprctl.telemetry.zenoh.security import zenoh_error
    from cdprctl.telemetry.zenoh.session import open_session
    from cdprctl.telemetry.zenoh.zenoh_files import missing_files

    problems = missing_files(args.zenoh_config)
    for p in problems:
        print(f"cdprctl {args.cmd}: error: --zenoh-config {p}", file=sys.stderr)
    if problems:
        return None
    endpoints = list(args.connect or ())
    if endpoints and all(_reachable(e) is False for e in endpoints):  # known now, not later
        print(f"cdprctl {args.cmd}: cannot connect to {', '.join(endpoints)}: {NOTHING_THERE}",
              file=sys.stderr)  # fmt: skip
        return None
    try:
        return open_session(
            mode="peer",
            listen=args.listen or (),
            connect=args.connect or (),
            multicast_scouting=not args.no_multicast_scouting,
            config_file=args.zenoh_config,
        )
    except Exception as exc:  # zenoh.ZError: endpoints, TLS, the configuration's values
        why = zenoh_error(exc)
        print(f"cdprctl {args.cmd}: error: cannot open a Zenoh session: {why}", file=sys.stderr)
        return None


def robot_status(session: Any, prefix: str, timeout: float = 3.0) -> dict[str, Any]:
    """The robot's status (name, limits, layout), asked again until it answers or ``timeout``
    s pass ({} then): a session just opened may not be routed to the daemon's queryable yet
    (behind a router, the second of two robots' status came back empty 3 runs of 3)."""
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        for r in session.get(f"{prefix}/status", timeout=min(1.0, max(left, 0.1))):
            if r.ok is not None:
                try:
                    return dict(json.loads(r.ok.payload.to_bytes()))
                except ValueError:
                    pass
        if time.monotonic() >= deadline:
            return {}
        time.sleep(0.1)


def unreached(args: argparse.Namespace) -> str:
    """Why a session reached no peer: nothing found by scouting, nothing listens at the
    endpoints, or what listens there refused this session (its credentials)."""
    endpoints = list(args.connect or ())
    if not endpoints:
        return ("no Zenoh peer found (multicast scouting finds none, or is off): give "
                "--connect ENDPOINT, the robot's --zenoh-listen")  # fmt: skip
    refused = [e for e in endpoints if _reachable(e)]
    if refused:
        return (f"{', '.join(refused)} accepts connections but refused this session: "
                "authentication failed (the user/password or certificate of "
                "--zenoh-config), or it is not a Zenoh peer")  # fmt: skip
    return f"cannot connect to {', '.join(endpoints)}: {NOTHING_THERE}"


NOTHING_THERE = "nothing listens there (is the daemon running, with --zenoh-listen on it?)"


def _reachable(endpoint: str) -> bool | None:
    """Whether something accepts a TCP connection at a tcp/ or tls/ endpoint (None: another
    kind, or not host:port)."""
    import socket

    proto, _, where = endpoint.partition("/")
    host, _, port = where.rpartition(":")
    if proto not in ("tcp", "tls") or not host or not port.isdigit():
        return None
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=1.0):
            return True
    except OSError:
        return False


def not_there(session: Any, args: argparse.Namespace, prefix: str) -> str:
    """Before a tool waits for the robot's answer: why it will not come, when that is known
    within a second or two — no peer reached (nothing listens, or the peer refused this
    session: its credentials) or no robot under ``prefix``; "" when the robot answers its
    status. A wrong password or robot name costs the second, not the reply's timeout."""
    deadline = time.monotonic() + PEER_WAIT
    while not peers(session) and time.monotonic() < deadline:
        time.sleep(0.05)
    if peers(session) and robot_status(session, prefix, timeout=2.0):
        return ""
    return why_no_answer(session, args, prefix)


PEER_WAIT = 1.0  # s: a session reaches its --connect peers within this (measured: < 0.1 s)


def peers(session: Any) -> list[Any]:
    return [*session.info.peers_zid(), *session.info.routers_zid()]


def why_no_answer(session: Any, args: argparse.Namespace, prefix: str,
                  command: bool = True) -> str:  # fmt: skip
    """What a tool that heard nothing from the robot can tell: nobody reached (nothing listens
    there, or a peer listens and refused this session: its credentials), reached but no robot
    under ``prefix``, or the robot is there and took no ``command`` (its ACL, or commands
    off) or, waiting for its state, publishes none."""
    if not peers(session):
        return unreached(args)
    status = robot_status(session, prefix, timeout=1.5)
    if not status:
        seen = sorted({str(r.ok.key_expr).rsplit("/", 1)[0] for r in
                       session.get("cdpr/*/status", timeout=1.0) if r.ok is not None})  # fmt: skip
        others = f" (robots there: {', '.join(seen)})" if seen else ""
        return (f"connected, but no robot answers under {prefix}{others}: check --robot (the "
                "robot's name in its config)")  # fmt: skip
    if not command:
        return f"{prefix} answers its status but publishes no state to this session"
    commands = status.get("commands") or {}
    if not commands.get("enabled", True):
        return f"{prefix} takes no commands (start it with --accept-commands)"
    return (f"{prefix} is there but did not answer: this account may not command it (the "
            "robot's ACL drops its commands without a reply; the daemon's log names each "
            "refusal: journalctl -u cdprctl | grep refused)")
