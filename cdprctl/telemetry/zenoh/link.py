"""The daemon's side of the gateway: it starts the gateway process, writes the snapshot,
forwards events and takes the validated commands. Used by the daemon's I/O thread only —
never by the loop."""

from __future__ import annotations

import queue
import time
from typing import Any

import numpy as np

from cdprctl.control.command_types import (
    Command,
    GripKind,
    GripperCommand,
    JogCommand,
    MoveCommand,
    PathCommand,
    SetTdaCommand,
    StopCommand,
    command,
)
from cdprctl.model.robot import RobotModel
from cdprctl.telemetry.helper import SnapshotLink
from cdprctl.telemetry.snapshot import timing_values


class TelemetryLink(SnapshotLink):
    def __init__(self, model: RobotModel, summary: dict[str, Any]):
        from cdprctl.telemetry.zenoh.gateway import gateway_main

        super().__init__(model, 1.0 / model.zenoh.state_rate)  # s: the state's rate
        self.commands: Any = self.queue(maxsize=32)
        self.events: Any = self.queue(maxsize=1000)
        self.said = self.ctx.SimpleQueue()  # the gateway's line on whom it reached
        self.dropped_events = 0
        self.start_helper("cdprctl-zenoh", "the Zenoh gateway", gateway_main, model,
                          self.snapshot.name, self.commands, self.events, self.stop, self.ready,
                          summary, self.said)  # fmt: skip
        self._next_timing = 0.0

    def announcement(self) -> list[tuple[str, bool]]:
        """What ``cdprctl run`` says once the gateway runs: (line, to stderr)."""
        from cdprctl.telemetry.zenoh.security import UNAUTHENTICATED_WARNING

        zc = self.model.zenoh
        out = []
        if zc.commands and zc.allow_unauthenticated_commands:
            out.append((f"warning: {UNAUTHENTICATED_WARNING}", True))
        reached = "" if self.said.empty() else self.said.get()  # it says where it listens
        listening = f", listening on {', '.join(zc.listen)}" if zc.listen and not reached else ""
        out.append((f"zenoh: {zc.key_prefix(self.model.name)}/{{state,timing,events,status}}, "
                    f"commands {'on' if zc.commands else 'off'}{listening}", False))  # fmt: skip
        if reached:
            out.append((reached, False))
        return out

    def due(self) -> bool:
        """Every tick of the daemon's I/O thread (it wakes at the state's rate)."""
        return True

    def write(self, values: dict[str, Any], stats: Any = None) -> None:
        """The loop's values (``snapshot.controller_values``) into the snapshot, the loop's
        timing (``stats``, the daemon's always) with them at ``zenoh.timing_rate``."""
        now = time.monotonic()
        if now >= self._next_timing:
            # percentiles over the cycles since the last report (docs/telemetry.md)
            dt = 1.0 / self.model.zenoh.timing_rate
            values["timing"] = timing_values(stats, round(dt / self.model.control.period))
            self._next_timing = now + dt
        self.snapshot.write(values)

    def event(self, t: float, text: str, kind: str = "event") -> None:
        try:
            self.events.put_nowait((kind, t, text))
        except queue.Full:
            self.dropped_events += 1

    def take_commands(self, limit: int = 32) -> list[Command]:
        out: list[Command] = []
        for _ in range(limit):
            try:
                kind, params = self.commands.get_nowait()
            except queue.Empty:
                break
            if kind == "move":
                out.append(
                    MoveCommand(
                        pose=np.array(params["pose"], dtype=float),
                        speed=params["speed"],
                        accel=params["accel"],
                    )
                )
            elif kind == "gripper":
                out.append(
                    GripperCommand(
                        gripper=int(params["gripper"]),
                        grip=GripKind(params["grip"]),
                        value=float(params["value"]),
                    )
                )
            elif kind == "set_tda":
                out.append(SetTdaCommand(tda=params["tda"]))
            elif kind == "jog":
                out.append(JogCommand(velocity=np.array(params["velocity"]), frame=params["frame"]))
            elif kind == "path":
                plan = params.get("plan")
                out.append(PathCommand(text=params["text"], name=params["name"],
                                       plan=None if plan is None else (plan, 0)))  # fmt: skip
            elif kind == "stop":
                out.append(StopCommand(category=int(params["category"])))
            else:
                out.append(command(kind))  # the kinds without fields
        return out

    def close(self) -> None:
        super().close()
        self.said.close()
