"""Lock-step soak: the controller against the simulated window-cleaning robot for a long
stretch of simulated time, random moves and random faults (seeded), the supervisor's
recoveries played like an operator would (reset, enable). Writes a JSON summary.

    .venv/bin/python tools/soak.py [--minutes 30] [--seed 1] [--out build/soak.json]
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import random
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdprctl.control.command_types import EnableCommand, MoveCommand, ResetCommand  # noqa: E402
from cdprctl.control.states import FaultKind, State  # noqa: E402
from cdprctl.experiments.closed_loop import ClosedLoop  # noqa: E402
from cdprctl.experiments.scenarios import Result, Scenario, Watch  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402
from sim_backend.contact import ContactRecorder  # noqa: E402
from sim_backend.faults import FaultEvent, FaultInjector  # noqa: E402


def fault_schedule(minutes: float, seed: int) -> list[FaultEvent]:
    """About one fault every 30 s: frame-loss bursts, drive faults, silent drives, lateral
    pushes (all transient: the robot can come back from each)."""
    rng = random.Random(seed)
    events = []
    t = rng.expovariate(1 / 30.0)
    while t < minutes * 60.0:
        kind = rng.choice(["frame_loss", "drive_fault", "silent_drive", "external_wrench"])
        value = {
            "frame_loss": rng.uniform(0.01, 0.2),
            "drive_fault": 0x2310,
            "external_wrench": (0.0, rng.uniform(-20, 20), rng.uniform(-20, 20), 0.0, 0.0, 0.0),
        }.get(kind, 0.0)
        events.append(
            FaultEvent(t, kind, rng.randrange(8), value, duration=rng.uniform(0.05, 2.0), ramp=0.5)
        )
        t += rng.expovariate(1 / 30.0)
    return events


def fault_key(kind: FaultKind | None, reason: str) -> str:
    """How a stop is counted: its kind, an internal fault by what failed, a drive's fault with
    its EMCY code."""
    internal = kind is FaultKind.INTERNAL  # keep what failed
    key = reason if internal else kind.value if kind else "?"
    # its EMCY code
    if kind is FaultKind.DRIVE_FAULT and "0x" in reason:
        key += " " + reason[reason.index("0x") :][:6]
    return key


def summary_of(minutes: float, seed: int, cycles: int, wall_s: float, comp: np.ndarray,
               events: list[FaultEvent], injector: FaultInjector, faults: collections.Counter,
               counts: collections.Counter, checked: Result, state: State,
               contact: ContactRecorder) -> dict:  # fmt: skip
    """The soak's JSON summary: the compute time per cycle (µs), the faults injected and
    detected, the state changes, the invariants' violations and the cables' contacts at the
    plant's true pose (``contact``: the plant's ContactRecorder)."""
    violations = {
        what: n
        for what, n in (
            ("non-finite torque", checked.nonfinite_torques),
            ("torque beyond limit", checked.torques_over_limit),
            ("tension outside limits while healthy", checked.tensions_outside_limits_while_healthy),
        )
        if n
    }
    return {
        "simulated_minutes": minutes,
        "seed": seed,
        "cycles": cycles,
        "wall_seconds": round(wall_s, 1),
        "compute_us": {
            "p50": round(float(np.percentile(comp, 50)), 1),
            "p99": round(float(np.percentile(comp, 99)), 1),
            "max": round(float(comp.max()), 1),
        },
        "faults_injected": dict(collections.Counter(e.kind for e in events)),
        "frames": dict(injector.counts),
        "faults_detected_by_reason": dict(faults),
        "state_changes": dict(counts),
        "invariant_violations": violations,
        "cable_contacts": len(contact.contacts),
        "closest_cables": contact.least_what,
        "final_state": state.value,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "soak.json")
    args = ap.parse_args()
    logging.getLogger("cdprctl.drivers").setLevel(logging.ERROR)
    model = load_robot(ROOT / "config" / "rowc.toml")
    rng = np.random.default_rng(args.seed)
    lo = np.array([0.9, 0.35, 0.35])  # m: the box the random targets come from
    hi = np.array([2.1, 0.35, 0.58])
    events = fault_schedule(args.minutes, args.seed)
    counts: collections.Counter[str] = collections.Counter()
    faults: collections.Counter[str] = collections.Counter()
    checked = Result(Scenario("soak", "soak"))
    watch = Watch(model, checked)  # the invariants of the fault matrix, every cycle
    compute = []
    wall0 = time.perf_counter()
    with ClosedLoop(model) as cl:
        injector = FaultInjector(events, seed=args.seed)
        injector.attach(cl.net)
        cl.startup()
        c = cl.controller
        c.submit(EnableCommand())
        n = round(args.minutes * 60.0 / cl.period)
        next_move = 1.0
        last_state = c.data.state
        for i in range(n):
            t = cl.net.time
            t0 = time.perf_counter_ns()
            cl.manager.step(t)
            compute.append((time.perf_counter_ns() - t0) / 1e3)
            cl.net.advance(cl.period)
            watch.check(c, cl.plant.position, measure_excursion=False)
            if c.data.state is not last_state:
                counts[f"-> {c.data.state.value}"] += 1
                if c.data.state is State.STOPPING or (
                    c.data.state is State.FAULT and last_state is not State.STOPPING
                ):
                    faults[fault_key(c.data.fault_kind, c.data.fault_reason)] += 1
                last_state = c.data.state
            if c.data.state is State.FAULT and i % 250 == 0:
                c.submit(ResetCommand())
            elif c.data.state is State.READY and i % 250 == 0:
                c.submit(EnableCommand())
            elif c.data.state is State.ENABLED and t >= next_move:
                goal = rng.uniform(lo, hi)
                c.submit(MoveCommand(pose=np.concatenate([goal, [0.0, 0.0, 0.0]])))
                counts["moves"] += 1
                next_move = t + 4.0
        contact = cl.plant.contact  # the cables at the plant's true pose, every step
    summary = summary_of(args.minutes, args.seed, int(n), time.perf_counter() - wall0,
                         np.array(compute), events, injector, faults, counts, checked,
                         c.data.state, contact)  # fmt: skip
    violations = summary["invariant_violations"]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))
    if violations:
        sys.exit(1)


if __name__ == "__main__":
    main()
