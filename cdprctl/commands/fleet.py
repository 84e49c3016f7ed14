"""``cdprctl robots`` and ``cdprctl zenoh-router``: the robots a Zenoh network holds, and a
router for them where no ``zenohd`` is installed (docs/fleet.md)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

from cdprctl.commands.parsing import command_parser
from cdprctl.commands.zenoh_session import (
    add_zenoh_arguments,
    peers,
    tool_session,
    unreached,
)

#: s: asked again this long after a robot was last found, for those whose queryables reach a
#: session just opened a little later (behind a router, measured: all within 25 ms of the
#: first; the first query, at once after opening, found none 6 times in 10)
SETTLE = 0.15
def add_parsers(sub: Any) -> None:
    p = command_parser(sub, "robots", "list the robots answering on the Zenoh network", robots,
                       config=False)  # fmt: skip
    p.add_argument("--json", action="store_true", help="a JSON list instead of lines")
    p.add_argument("--under", default="cdpr/**", metavar="KEYEXPR",
                   help="where the robots' prefixes are (** for anywhere)")  # fmt: skip
    p.add_argument("--timeout", type=float, default=1.0, help="s to wait for answers (≤ 1 s)")
    add_zenoh_arguments(p, robot=False)
    p = command_parser(sub, "zenoh-router", "a Zenoh router for a fleet (zenohd's stand-in)",
                       zenoh_router, config=False)  # fmt: skip
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help="where robots and tools connect (default tcp/0.0.0.0:7447)")  # fmt: skip
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="another router")
    p.add_argument("--zenoh-config", default="", metavar="FILE",
                   help="Zenoh JSON5 (ACL, TLS, user/password)")  # fmt: skip
    p.add_argument("--duration", type=float, default=0.0, help="s to run (0: until Ctrl-C)")


def robots(args: argparse.Namespace) -> int:
    """Every robot whose gateway answers its status on the network this session reaches: its
    name, state, key prefix, Zenoh id and address (the endpoint this tool reached it by, or
    where it listens), one line each; within --timeout s (1). Exit 0 with at least one robot,
    1 with none (and why), 2 when no session opens."""
    if not 0.0 < args.timeout <= 1.0:
        print(f"cdprctl robots: error: --timeout {args.timeout:g}: give a time in (0, 1] s",
              file=sys.stderr)  # fmt: skip
        return 2
    start = time.monotonic()  # the answer within --timeout of this, the session's opening too
    session = tool_session(args)
    if session is None:
        return 2
    try:
        until = max(start + args.timeout, time.monotonic() + 0.2)
        found = find_robots(session, f"{args.under.rstrip('/')}/status", until)
        why = "" if found or not peers(session) else (
            "connected, but no cdprctl gateway answers its status there (is each robot's "
            "daemon run with --zenoh, and does its ACL let this account query?)")
        why = why if found or why else unreached(args)
    finally:
        session.close()
    if args.json:
        print(json.dumps(found, indent=1))
    else:
        for r in found:
            print(robot_line(r))
    if not found:
        print(f"cdprctl robots: no robot answers under {args.under}: {why}", file=sys.stderr)
    return 0 if found else 1


def find_robots(session: Any, key: str, deadline: float) -> list[dict[str, Any]]:
    """The cdprctl gateways answering ``key`` (a wildcard on ``P/status``) before
    ``deadline`` (monotonic s): asked every 30 ms until ``SETTLE`` s have brought no new one
    (with none, until the deadline)."""
    import zenoh

    found: dict[str, dict[str, Any]] = {}
    settled = math.inf
    while (now := time.monotonic()) < min(deadline, settled):
        addresses = {str(link.zid): str(link.dst) for link in session.info.links()}
        replies = session.get(key, target=zenoh.QueryTarget.ALL,
                              consolidation=zenoh.ConsolidationMode.NONE,
                              timeout=max(deadline - now, 0.01))  # fmt: skip
        for reply in replies:
            robot = _robot(reply, addresses)
            if robot and robot["prefix"] not in found:
                found[robot["prefix"]] = robot
                settled = time.monotonic() + SETTLE
        time.sleep(0.03)
    return [found[k] for k in sorted(found)]


def _robot(reply: Any, addresses: dict[str, str]) -> dict[str, Any] | None:
    """One reply as a robot, None when it is not a cdprctl gateway's status."""
    if reply.ok is None:
        return None
    try:
        body = json.loads(reply.ok.payload.to_bytes())
    except ValueError:
        return None
    if not isinstance(body, dict) or not str(body.get("schema", "")).startswith("cdprctl/"):
        return None
    net = body.get("zenoh") or {}
    zid = str(net.get("zid") or (reply.replier_id.zid if reply.replier_id else ""))
    return {
        "robot": (body.get("config") or {}).get("robot", "?"),
        "state": body.get("state"),
        "fault": body.get("fault") or "",
        "prefix": str(reply.ok.key_expr).rsplit("/", 1)[0],
        "zid": zid,
        "reached_at": _reached_at(addresses.get(zid, ""), net.get("listen", [])),
        "listen": net.get("listen", []),
        "connect": net.get("connect", []),
        "simulated": (body.get("config") or {}).get("simulated"),
    }


def _reached_at(dst: str, listen: list[str]) -> str:
    """The endpoint of this session's own link to the robot when the session opened it (its
    port one the robot listens on); "" when the link is the robot's to this session (its
    outgoing port says nothing of where it is) or there is none (through a router)."""
    port = dst.rpartition(":")[2]
    return dst if dst and any(str(e).rpartition(":")[2] == port for e in listen) else ""


def robot_line(r: dict[str, Any]) -> str:
    where = (f"at {r['reached_at']}" if r["reached_at"] else
             f"via {', '.join(r['connect'])}" if r["connect"] else "via a peer")  # fmt: skip
    listens = f", listens on {', '.join(r['listen'])}" if r["listen"] else ""
    fault = f" ({r['fault']})" if r["fault"] else ""
    sim = " (simulated)" if r.get("simulated") else ""
    return (f"{r['robot']:<12} {r['state'] or '?':<9} {r['prefix']:<20} zid {r['zid'][:8]} "
            f"{where}{listens}{sim}{fault}")  # fmt: skip


def zenoh_router(args: argparse.Namespace) -> int:
    """A Zenoh router in this process (eclipse-zenoh's own, mode "router"): robots and tools
    connect to it instead of to each other (docs/fleet.md). Says who connects and leaves,
    one line each; Ctrl-C ends it."""
    from cdprctl.telemetry.zenoh.security import zenoh_error
    from cdprctl.telemetry.zenoh.session import open_session
    from cdprctl.telemetry.zenoh.zenoh_files import missing_files

    problems = missing_files(args.zenoh_config)
    for p in problems:
        print(f"cdprctl zenoh-router: error: --zenoh-config {p}", file=sys.stderr)
    if problems:
        return 2
    listen = args.listen or ["tcp/0.0.0.0:7447"]
    try:
        session = open_session(mode="router", listen=listen, connect=args.connect or (),
                               multicast_scouting=False, config_file=args.zenoh_config)  # fmt: skip
    except Exception as exc:  # zenoh.ZError: the endpoint taken, TLS, the configuration
        why = zenoh_error(exc)
        print(f"cdprctl zenoh-router: error: cannot open the router: {why} (is another router "
              "listening there? --listen another port)", file=sys.stderr)  # fmt: skip
        return 2
    print(f"zenoh-router: zid {session.info.zid()}, listening on {', '.join(listen)}", flush=True)

    def on_event(event: Any) -> None:
        import zenoh

        sign = "+" if event.kind == zenoh.SampleKind.PUT else "-"
        tr = event.transport
        print(f"zenoh-router: {sign} {tr.whatami} {tr.zid}", flush=True)

    listener = session.info.declare_transport_events_listener(on_event)
    try:
        end = time.monotonic() + args.duration if args.duration > 0 else None
        while end is None or time.monotonic() < end:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        listener.undeclare()
        session.close()
    return 0
