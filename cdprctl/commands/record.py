"""``cdprctl record``: a robot's telemetry over Zenoh into CSV files (and MCAP: Foxglove's
typed scene, ROS 2's topics), which ``cdprctl report`` draws."""

from __future__ import annotations

import argparse
import csv
import json
import sys
import threading
import time
from pathlib import Path
from typing import Any

from cdprctl.commands.parsing import command_parser
from cdprctl.commands.zenoh_session import (
    add_zenoh_arguments,
    key_prefix,
    robot_status,
    tool_session,
    why_no_answer,
)


def add_parser(sub: Any) -> None:
    p = command_parser(
        sub, "record", "record a robot's telemetry to CSV files (and MCAP)", record, config=False
    )
    p.add_argument("--output", required=True, metavar="DIR")
    p.add_argument(
        "--mcap",
        action="store_true",
        help="also write DIR/telemetry.mcap: every payload as received and the typed 3D "
        "scene (frames, cables coloured by tension, platform, log), for Foxglove; and "
        "DIR/ros2.mcap: the ROS 2 link's topics (/tf, joint_states, pose, ...), for ros2 bag "
        "play and Foxglove's ROS 2 panels (docs/ros2.md)",
    )
    p.add_argument("--duration", type=float, help="s; default: until Ctrl-C")
    add_zenoh_arguments(p)



def record(args: argparse.Namespace) -> int:
    """Writes DIR/state.csv, DIR/timing.csv, DIR/events.csv and DIR/meta.json (the robot's
    status: limits, cables) until --duration or Ctrl-C, and with --mcap DIR/telemetry.mcap
    (Foxglove); `cdprctl report DIR` draws them."""
    prefix = key_prefix(args)
    if prefix is None:
        return 2
    out = Path(args.output)
    lock = threading.Lock()
    rows: dict[str, list[Any]] = {"state": [], "timing": [], "events": []}
    raw: list[tuple[int, str, bytes]] = []  # (receive time ns, key, payload), for MCAP

    def on_sample(sample: Any) -> None:
        key = str(sample.key_expr).rsplit("/", 1)[-1]
        data = sample.payload.to_bytes()
        try:
            body = json.loads(data)
        except ValueError:
            return
        with lock:
            rows[key].append(body)
            if args.mcap:
                raw.append((time.time_ns(), key, data))

    session = tool_session(args)
    if session is None:
        return 2
    out.mkdir(parents=True, exist_ok=True)
    try:
        subs = [
            session.declare_subscriber(f"{prefix}/{k}", on_sample)
            for k in ("state", "timing", "events")
        ]
        status = robot_status(session, prefix)
        (out / "meta.json").write_text(json.dumps(status, indent=1))
        end = time.monotonic() + args.duration if args.duration else float("inf")
        until = f"for {args.duration:g} s" if args.duration else "until Ctrl-C"
        found = "" if status else f" (no status yet: {why_no_answer(session, args, prefix, False)})"
        print(f"cdprctl record: recording {prefix} into {out} {until}{found}", flush=True)
        next_note = time.monotonic() + 5.0
        try:
            while time.monotonic() < end:
                time.sleep(0.2)
                if time.monotonic() >= next_note:  # a sign of life, every 5 s
                    next_note += 5.0
                    with lock:
                        got = len(rows["state"])
                    print(f"cdprctl record: {got} states so far", flush=True)
        except KeyboardInterrupt:
            pass
        for s in subs:
            s.undeclare()
        with lock:
            heard = bool(rows["state"])
        why = "" if heard else why_no_answer(session, args, prefix, command=False)
    finally:
        session.close()
    mcaps: list[str] = []  # the MCAP files written
    with lock:
        n = _write_csvs(out, rows)
        if args.mcap:
            from cdprctl.telemetry.mcap.mcap_log import write_mcap

            layout = status.get("config", {}).get("layout")
            write_mcap(out / "telemetry.mcap", prefix, raw, layout)
            mcaps.append("telemetry.mcap")
            if layout:  # the ROS 2 messages need the robot's cables
                from cdprctl.telemetry.mcap.ros2_mcap import write_ros2_mcap

                write_ros2_mcap(out / "ros2.mcap", raw, status)
                mcaps.append("ros2.mcap")
    print(
        f"cdprctl record: {n['state']} states, {n['timing']} timing, {n['events']} events → {out}"
        + (f" (CSV, {', '.join(mcaps)})" if mcaps else "")
    )
    if not n["state"]:
        print(f"cdprctl record: no state recorded: {why}", file=sys.stderr)
        return 2
    return 0


def _write_csvs(out: Path, rows: dict[str, list[Any]]) -> dict[str, int]:
    # a state stamped 0.0 is from before the loop's first cycle (a recording started with the
    # daemon): the loop's clock is the monotonic one, thousands of s on, and that one row
    # squeezed every plot's run into its right edge. Left out; the start-up's events (0.0
    # too) are kept in events.csv, before the recording's first state as they were.
    states = [s for s in rows["state"] if s.get("time")]
    rows = {**rows, "state": states}
    if states:
        m = len(states[0]["tensions"])
        names = states[0]["cables"]
        head = ["time", "state", "tda_method", "tda_status", "x", "y", "z", "roll", "pitch", "yaw"]
        head += ["ref_" + a for a in ("x", "y", "z", "rx", "ry", "rz")]
        head += ["err_" + a for a in ("x", "y", "z", "rx", "ry", "rz")]
        head += [f"t_{c}" for c in names] + [f"tau_{c}" for c in names]
        head += ["true_x", "true_y", "true_z"]
        grips = [g["cable"] for g in states[0].get("grippers", [])]
        for gname in grips:
            head += [
                f"{k}_{gname}" for k in ("grip_state", "grip_travel", "grip_force", "grip_target")
            ]
        with open(out / "state.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(head)
            for s in states:
                if len(s["tensions"]) != m:
                    continue
                w.writerow(
                    [s["time"], s["state"], s["tda"]["method"], s["tda"]["status"]]
                    + s["pose"]["position"]
                    + s["pose"]["rpy"]
                    + s["reference"]
                    + s["tracking_error"]
                    + s["tensions"]
                    + s["torques"]
                    + s.get("true_position", ["", "", ""])
                    + [
                        g.get(k)
                        for g in s.get("grippers", [])[: len(grips)]
                        for k in ("state", "travel", "force", "target")
                    ]
                )
    if rows["timing"]:
        keys = [k for k in rows["timing"][0] if k != "schema"]
        with open(out / "timing.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(keys)
            for t in rows["timing"]:
                w.writerow([t.get(k) for k in keys])
    with open(out / "events.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "kind", "text"])
        for e in rows["events"]:
            w.writerow([e.get("time"), e.get("kind"), e.get("text")])
    return {k: len(v) for k, v in rows.items()}
