"""``cdprctl send``, ``monitor`` and ``record``: tools for people, over Zenoh."""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any

from cdprctl.commands.parsing import command_parser
from cdprctl.commands.zenoh_session import (
    add_zenoh_arguments,
    key_prefix,
    not_there,
    robot_status,
    tool_session,
    why_no_answer,
)
from cdprctl.core.angles import user_angles


def add_parsers(sub: Any) -> None:
    p = command_parser(sub, "send", "send a command to a robot over Zenoh", send, config=False)
    p.add_argument("kind", help="command: enable, disable, stop, reset, move, set_tda, ...")
    p.add_argument("fields", nargs="*", metavar="KEY=VALUE")
    p.add_argument("--json", default="", help="the payload as one JSON object")
    p.add_argument(
        "--file",
        metavar="FILE",
        help="path: the path file (CSV or G-code) as the payload's text, its name as name",
    )
    p.add_argument("--timeout", type=float, default=5.0, help="s to wait for the reply")
    add_zenoh_arguments(p)

    p = command_parser(
        sub, "monitor", "a live terminal view of a robot's telemetry", monitor, config=False
    )
    p.add_argument("--once", action="store_true", help="print one view and exit")
    p.add_argument("--timeout", type=float, default=10.0, help="s to wait for data (--once)")
    add_zenoh_arguments(p)


def _value(text: str) -> Any:
    if "," in text:
        return [_value(x) for x in text.split(",") if x.strip()]
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    if text in ("true", "false"):
        return text == "true"
    return text


def fields_payload(fields: list[str]) -> dict[str, Any]:
    """A command's payload from ``send``'s ``KEY=VALUE`` fields (a comma list is a vector:
    position=1.8,0.35,0.5); ValueError names a field that is not one."""
    payload: dict[str, Any] = {}
    for f in fields:
        if "=" not in f:
            raise ValueError(f"{f!r} is not KEY=VALUE")
        k, v = f.split("=", 1)
        if k == "rpy":  # radians, or degrees where a value ends in deg: sent in radians
            angles = user_angles(v.split(","))
            if isinstance(angles, str):
                raise ValueError(f"rpy: {angles}")
            payload[k] = angles
        else:
            payload[k] = _value(v)
    return payload


def send(args: argparse.Namespace) -> int:
    """Send a command and wait for its reply. Fields as key=value (a comma list is a vector:
    position=1.8,0.35,0.5) or as one JSON object with --json. Commands: enable, disable, stop
    (category 0: the drives off at once onto the brakes, 1: decelerate then off, 2: decelerate
    and hold, the default), reset, move (position m, rpy rad, max_velocity m/s, max_acceleration
    m/s²), set_tda (method, nu, direction), impose (cable, quantity energy|tension|deformation,
    value J|N|m), gripper (gripper = its cable, and travel m, force N or release=true), jog
    (velocity m/s and rad/s, frame base|platform; repeat it, or use ``cdprctl jog``), path
    (--file FILE: checked whole before it is accepted), pause, resume, abort. Exit 0 accepted, 1
    rejected, 2 no reply."""
    prefix = key_prefix(args)
    if prefix is None:
        return 2
    if args.json:
        try:
            payload = json.loads(args.json)
        except ValueError as exc:
            print(f"cdprctl send: error: --json is not JSON ({exc})", file=sys.stderr)
            return 2
        if not isinstance(payload, dict):
            print("cdprctl send: error: --json must be a JSON object", file=sys.stderr)
            return 2
    else:
        try:
            payload = fields_payload(args.fields)
        except ValueError as exc:
            print(f"cdprctl send: error: {exc}", file=sys.stderr)
            return 2
    if args.file:
        try:
            payload["text"] = Path(args.file).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            print(f"cdprctl send: error: --file = {args.file}: {exc}", file=sys.stderr)
            return 2
        payload.setdefault("name", Path(args.file).name)
    payload.setdefault("id", uuid.uuid4().hex[:12])
    got: dict[str, Any] = {}
    done = threading.Event()

    def on_reply(sample: Any) -> None:
        try:
            body = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        if body.get("id") == payload["id"]:
            got.update(body)
            done.set()

    session = tool_session(args)
    if session is None:
        return 2
    try:
        # declared before the status query: the gateway's answer to it, on the same route,
        # comes after the declaration reached it (this was a fixed 0.3 s sleep)
        sub = session.declare_subscriber(f"{prefix}/reply/{args.kind}", on_reply)
        early = not_there(session, args, prefix)  # known now: not after the reply's timeout
        if not early:
            session.put(f"{prefix}/cmd/{args.kind}", json.dumps(payload))
            done.wait(args.timeout)
            why = "" if got else why_no_answer(session, args, prefix)
        sub.undeclare()
    finally:
        session.close()
    if early:
        print(f"cdprctl send: {args.kind} not sent: {early}", file=sys.stderr)
        return 2
    if not got:
        print(f"cdprctl send: no reply from {prefix} in {args.timeout:g} s: {why}",
              file=sys.stderr)  # fmt: skip
        return 2
    if got.get("ok"):
        print(f"{args.kind}: accepted")
        return 0
    print(f"{args.kind}: rejected: {got.get('reason')}", file=sys.stderr)
    return 1


def _bar(t: float, lo: float, hi: float, width: int = 30) -> str:
    f = 0.0 if hi <= lo else min(1.0, max(0.0, (t - lo) / (hi - lo)))
    n = round(f * width)
    return "[" + "#" * n + "." * (width - n) + "]"


def safety_line(safety: dict[str, Any]) -> str:
    """The safety state in one line (docs/safety.md): chain, brakes, stop, the brake test."""
    cat = safety.get("stop_category")
    test = safety.get("brake_test") or {}
    if test.get("time"):
        tested = (f"brake test {'passed' if test.get('passed') else 'FAILED'} {test['time']}, "
                  f"next due {test.get('next_due')}")  # fmt: skip
    else:
        tested = "no brake test on record" + ("" if test.get("required") else " (not required)")
    return (f"safety   chain {safety.get('chain')}, brakes {safety.get('brakes')}, stop "
            f"category {'—' if cat is None else cat}"
            + (f" ({safety['tripped']})" if safety.get("tripped") else "")
            + f"; {tested}")  # fmt: skip


def friction_status(f: dict[str, Any]) -> str:
    """The winches' friction in use in one line: the calibration's or the robot file's."""
    c = f.get("coulomb") or [0.0]
    where = f"calibrated {f['time']}" if f.get("source") == "calibrated" else "the robot file's"
    return f"friction {where}: Coulomb {min(c):.3g}..{max(c):.3g} N·m per winch"


def path_line(path: dict[str, Any]) -> str:
    """A path's progress in one line: segment k of n, the share of its planned time played
    (of its segments, from a daemon that does not say the times) and the time left."""
    k, n, state = path.get("segment", 0), path.get("segments", 0), path.get("state", "")
    played, left = path.get("elapsed"), path.get("time_left")
    if isinstance(played, (int, float)) and isinstance(left, (int, float)) and played + left > 0:
        done = played / (played + left)
    else:
        done = ((k - 1) + (path.get("fraction") or 0.0)) / n if n else 0.0
    line = f"path     segment {k} of {n} ({state}), {done:.0%}"
    if isinstance(left, (int, float)) and state in ("running", "dwell", "paused"):
        line += f", {left:.1f} s left"
    return line + (f", {_bar(done, 0.0, 1.0)}" if state in ("running", "dwell") else "")


def render(state: dict[str, Any], timing: dict[str, Any] | None, meta: dict[str, Any]) -> str:
    p, rpy = state["pose"]["position"], state["pose"]["rpy"]
    err = state["tracking_error"]
    lines = [
        f"{meta.get('robot', '?')}  state {state['state']}"
        + (f"  FAULT ({state['fault_kind']}): " if state.get("fault_kind") else "  FAULT: ")
        * bool(state.get("fault"))
        + (state.get("fault") or "")
        + f"  t {state['time']:.2f} s  cycle {state['cycle']}",
        f"pose     [{p[0]:8.4f} {p[1]:8.4f} {p[2]:8.4f}] m   rpy [{rpy[0]:7.4f} "
        f"{rpy[1]:7.4f} {rpy[2]:7.4f}] rad",
        f"target   [{state['target'][0]:8.4f} {state['target'][1]:8.4f} "
        f"{state['target'][2]:8.4f}] m   tracking error "
        f"{1e3 * sum(x * x for x in err[:3]) ** 0.5:6.2f} mm",
        f"TDA      {state['tda']['method']} ({state['tda']['status']})"
        + (
            f"  feedback saturated: the cables give {state['tda']['saturation']:.0%} of it"
            if (state["tda"].get("saturation") or 1.0) < 1.0
            else ""
        ),
        *([f"WARNING  {state['warning']}"] if state.get("warning") else []),
        *([safety_line(state["safety"])] if state.get("safety") else []),
        *([friction_status(meta["friction"])] if meta.get("friction") else []),
        *([path_line(state["path"])] if state.get("path") else []),
        "tensions",
    ]
    lo = meta.get("tension_min") or [0.0] * len(state["tensions"])
    hi = meta.get("tension_max") or [max(state["tensions"]) or 1.0] * len(state["tensions"])
    for name, t, a, b, tau in zip(
        state["cables"], state["tensions"], lo, hi, state["torques"], strict=False
    ):
        lines.append(f"  {name:>4} {_bar(t, a, b)} {t:8.1f} N  [{a:g}, {b:g}]  τ {tau:7.3f} N·m")

    def mm(x: Any) -> str:
        return f"{x * 1e3:6.1f}" if isinstance(x, (int, float)) else "     —"

    for g in state.get("grippers", []):
        lines.append(
            f"gripper {g['cable']:>3}: {g['state'] or '?':9s} travel {mm(g['travel'])} mm "
            f"(target {mm(g['target'])})  squeeze {g['force'] or 0.0:5.1f} N  "
            f"energy {g['energy'] or 0.0:6.2f} J"
        )
    if timing:
        lines.append(
            f"loop     lateness p50 {timing['lateness_p50_us']:.0f} / p99 "
            f"{timing['lateness_p99_us']:.0f} / max {timing['lateness_max_us']:.0f} us, "
            f"compute p50 {timing['compute_p50_us']:.0f} us, missed {timing['missed']:.0f}"
        )
    return "\n".join(lines)


def monitor(args: argparse.Namespace) -> int:
    """Pose, tensions as bars against their limits, state and loop timing, refreshed as `state`
    arrives. Ctrl-C ends it."""
    prefix = key_prefix(args)
    if prefix is None:
        return 2
    latest: dict[str, Any] = {}
    new = threading.Event()

    def on_sample(sample: Any) -> None:
        key = str(sample.key_expr).rsplit("/", 1)[-1]
        try:
            latest[key] = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        if key == "state":
            new.set()

    session = tool_session(args)
    if session is None:
        return 2
    try:
        subs = [session.declare_subscriber(f"{prefix}/{k}", on_sample) for k in ("state", "timing")]
        meta = robot_status(session, prefix).get("config", {})
        start = time.monotonic()
        while True:
            if not new.wait(0.5):
                if args.once and time.monotonic() - start > args.timeout:
                    why = why_no_answer(session, args, prefix, command=False)
                    print(f"cdprctl monitor: no state from {prefix} in {args.timeout:g} s: "
                          f"{why}", file=sys.stderr)  # fmt: skip
                    return 2
                continue
            new.clear()
            view = render(latest["state"], latest.get("timing"), meta)
            if args.once:
                print(view)
                return 0
            print("\x1b[H\x1b[2J" + view, flush=True)
            time.sleep(0.1)  # 10 frames/s are enough for a person
    except KeyboardInterrupt:
        return 0
    finally:
        for s in subs:
            s.undeclare()
        session.close()
