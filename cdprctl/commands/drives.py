"""``cdprctl drives scan --config FILE``: the CiA 402 drives on the configured buses, read-only,
with a verdict per node (commissioning; docs/drivers.md "Commissioning")."""

from __future__ import annotations

import argparse
import inspect
import json
import sys
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report
from cdprctl.commands.sim import add_bus_arguments, bus_overrides, refuse_in_process_bus

EXAMPLES = """examples:
  cdprctl drives scan --config robot.toml --can-interface socketcan --can-channel can0 --json
  # the simulated robot in another process (cdprctl sim ... with the same two options):
  cdprctl drives scan --config config/rowc.toml --can-interface udp_multicast \\
      --can-channel 239.74.163.9
"""


def add_parser(sub: Any) -> None:
    p = sub.add_parser("drives", help="the CiA 402 drives on the buses: scan (read-only)")
    actions = p.add_subparsers(dest="drives_action", metavar="ACTION", required=True)
    s = command_parser(
        actions, "scan", "every node on the configured buses and whether it can run cdprctl "
        "(read-only)", scan, description=inspect.cleandoc(scan.__doc__ or ""), epilog=EXAMPLES,
    )  # fmt: skip
    s.set_defaults(cmd="drives scan")  # for the shared options' messages
    add_bus_arguments(s)
    s.add_argument("--listen", type=float, default=1.0, metavar="S",
                   help="seconds to listen for heartbeats and answers (default 1)")  # fmt: skip
    s.add_argument("--sdo-timeout", type=float, default=0.3, metavar="S",
                   help="seconds a drive has to answer each SDO upload (default 0.3)")  # fmt: skip
    s.add_argument("--json", action="store_true", help="one JSON document on stdout")


def scan(args: argparse.Namespace) -> int:
    """Every node on the configured buses (a node is found by its answer to an SDO upload of
    0x1000, or by its heartbeat): NMT state, identity 0x1018, device type 0x1000, supported
    modes 0x6502, rated torque 0x6076, the optional objects cdprctl writes, its PDO mappings;
    and per node "can run cdprctl in csp/cst: yes" or "no: why", and what the set-up would
    skip of what is absent (a value out of a drive's range shows only when the set-up writes
    it). Read-only: SDO uploads only, no NMT command, no SYNC. Exit 0 when every configured
    drive is there and can run its configured mode, 1 otherwise (or a config error), 2 a bad
    option."""
    from drivers.buses import media_key, media_of, open_bus
    from drivers.cia402.scan import judge, judge_bus, scan_bus
    from drivers.errors import DriverInitializationError

    model = load_or_report(args.config)
    if model is None:
        return 1
    cfg = model.drives
    if cfg.driver != "cia402":
        print(f"cdprctl drives scan: [drives] driver = {cfg.driver!r}: the scan reads CiA 402 "
              "drives (driver = \"cia402\")", file=sys.stderr)  # fmt: skip
        return 2
    for name, value in (("--listen", args.listen), ("--sdo-timeout", args.sdo_timeout)):
        if not 0 < value <= 60:
            print(f"cdprctl drives scan: error: {name} = {value} s must be > 0 and at most 60",
                  file=sys.stderr)  # fmt: skip
            return 2
    overrides = bus_overrides(args)
    if refuse_in_process_bus("cdprctl drives scan", model, overrides, False, has_sim=False):
        return 2
    out: list[dict[str, Any]] = []
    found = able = wanted = 0
    for b in media_of(cfg.buses, overrides):
        key = media_key(cfg.buses[b], overrides, b)
        configured: dict[int, tuple[int, str]] = {}  # node → (cable index, its DCF)
        for k, bus_cfg in enumerate(cfg.buses):
            if media_key(bus_cfg, overrides, k) == key:
                for j, (cable, node) in enumerate(zip(bus_cfg.cables, bus_cfg.node_ids,
                                                      strict=True)):  # fmt: skip
                    configured[node] = (cable, bus_cfg.dcf_of(j))
        try:
            bus = open_bus(cfg.buses[b], overrides, b)
        except DriverInitializationError as exc:
            print(f"cdprctl drives scan: {exc}", file=sys.stderr)
            return 1
        try:
            reports = scan_bus(bus, args.listen, args.sdo_timeout)
        finally:
            bus.shutdown()
        for r in reports:
            where = configured.get(r.node)
            judge(r, None if where is None else where[0], cfg, "" if where is None else where[1])
        judge_bus(reports)
        missing = sorted(set(configured) - {r.node for r in reports})
        wanted += len(configured)
        found += len(configured) - len(missing)
        able += sum(r.can_run_configured for r in reports)
        medium = {"bus": b, "interface": cfg.buses[b].interface, "channel": cfg.buses[b].channel,
                  "configured_nodes": sorted(configured), "missing_nodes": missing,
                  "nodes": [r.as_json() for r in reports]}  # fmt: skip
        medium.update({k: v for k, v in overrides.items() if k in ("interface", "channel")})
        out.append(medium)
        if not args.json:
            _print_medium(medium, reports)
    ok = able == wanted
    summary = (f"{found} of {wanted} configured drives found, {able} can run their configured "
               "mode")  # fmt: skip
    if args.json:
        print(json.dumps({"robot": model.name, "ok": ok, "summary": summary, "buses": out},
                         indent=1))  # fmt: skip
    else:
        print(summary)
    return 0 if ok else 1


def _print_medium(medium: dict, reports: list) -> None:
    nodes = ", ".join(map(str, medium["configured_nodes"]))
    print(f"bus {medium['bus']}: {medium['interface']} {medium['channel']} "
          f"(configured nodes {nodes})")  # fmt: skip
    for r in reports:
        who = f"node {r.node}" + (f" (drive of cable index {r.cable})" if r.cable is not None
                                  else " (not configured)")  # fmt: skip
        print(f"  {who}: {r.device_name or 'no device name'}; {r.nmt}")
        caps = r.capabilities
        if caps is None:
            print("    answers no SDO")
            continue
        ident = ", ".join(f"{k} 0x{v:08X}" for k, v in (caps.identity or {}).items())
        print(f"    identity: {ident or 'none (0x1018)'}")
        device = "0x1000 not readable" if caps.device_type is None else (
            f"device type 0x{caps.device_type:08X} (profile {caps.device_type & 0xFFFF})"
        )  # fmt: skip
        rated = "no 0x6076" if caps.rated_torque is None else f"0x6076 = {caps.rated_torque} mN·m"
        print(f"    {device}; {caps.modes_text()}; {rated}")
        for name, text in r.pdos.items():
            print(f"    {name}: {text}")
        for name, verdict in r.verdicts.items():
            mark = "  [configured]" if r.configured_mode == name else ""
            print(f"    can run cdprctl in {name}: {verdict}{mark}")
        for line in r.would_skip:
            print(f"    would skip {line}")
    for n in medium["missing_nodes"]:
        print(f"  node {n}: configured, not found (no SDO answer, no heartbeat: powered? "
              "wired? its node id?)")  # fmt: skip
