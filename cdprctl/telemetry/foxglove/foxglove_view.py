"""The live 3D view: a process beside the loop's (like the Zenoh gateway) serving Foxglove's
WebSocket protocol with ``foxglove-sdk``. It reads the loop's shared snapshot at
``[foxglove] rate`` and logs the scene (``foxglove_messages.py``); events arrive on a queue
and become ``Log`` messages. It takes no commands. The daemon's side is ``FoxgloveLink``."""

from __future__ import annotations

import contextlib
import json
import queue
import time
from typing import Any

from cdprctl.model.robot import RobotModel
from cdprctl.telemetry.helper import NewStates, SnapshotLink, paced
from cdprctl.telemetry.snapshot import SharedSnapshot


def foxglove_main(
    model: RobotModel,
    snapshot_name: str,
    events: Any,
    stop: Any,
    ready: Any,
    host: str,
    port: int,
) -> None:
    import foxglove
    from foxglove.channels import FrameTransformsChannel, LogChannel, SceneUpdateChannel

    from cdprctl.core.realtime import loop_cpu, yield_to_the_loop
    from cdprctl.telemetry.foxglove.foxglove_messages import (
        SIGNALS_SCHEMA,
        TOPICS,
        SceneMessages,
        log_message,
        signals,
        transforms,
    )
    from cdprctl.telemetry.foxglove.scene import SceneBuilder, SceneLayout
    from cdprctl.telemetry.zenoh.schema import clearance_parts, state_payload

    yield_to_the_loop(loop_cpu(model.control.cpu))  # best effort, as the gateway's
    snap = SharedSnapshot(model.n_cables, snapshot_name, g=len(model.grippers))
    ctx = foxglove.Context()
    try:
        server = foxglove.start_server(name=f"cdprctl {model.name}", host=host, port=port,
                                       context=ctx)  # fmt: skip
    except Exception as exc:  # the daemon prints it (telemetry/helper.py)
        snap.close()
        raise OSError(f"cannot serve on {host}:{port} ({exc}): give another port with "
                      "--foxglove HOST:PORT or [foxglove] listen") from None
    tf = FrameTransformsChannel(TOPICS["tf"], context=ctx)
    scene_ch = SceneUpdateChannel(TOPICS["scene"], context=ctx)
    log_ch = LogChannel(TOPICS["log"], context=ctx)
    sig_ch = foxglove.Channel(
        TOPICS["signals"],
        message_encoding="json",
        schema=foxglove.Schema(name="cdprctl.signals", encoding="jsonschema",
                               data=json.dumps(SIGNALS_SCHEMA).encode()),
        context=ctx,
    )  # fmt: skip
    layout = SceneLayout.from_model(model)
    builder, messages = SceneBuilder(layout), SceneMessages(layout)
    names = list(layout.names)
    grippers = [g.name for g in model.grippers]
    parts = clearance_parts(model)

    def publish(s: Any) -> None:
        now_ns = time.time_ns()
        state = state_payload(s, names, "", grippers, parts=parts)
        sc = builder.build(state)
        if sc is not None:
            tf.log(transforms(sc, now_ns), log_time=now_ns)
            scene_ch.log(messages.update(sc, now_ns), log_time=now_ns)
        sig_ch.log(signals(state), log_time=now_ns)

    new_states = NewStates(snap, "cdprctl-foxglove", publish)
    ready.set()
    try:
        for _ in paced(stop, 1.0 / model.foxglove.rate):
            now_ns = time.time_ns()
            while True:
                try:
                    kind, _t, text = events.get_nowait()
                except queue.Empty:
                    break
                log_ch.log(log_message(now_ns, kind, text), log_time=now_ns)
            new_states()
    finally:
        server.stop()
        snap.close()


class FoxgloveLink(SnapshotLink):
    """The daemon's side: starts the view process, writes its snapshot, forwards events.
    Used by the daemon's I/O thread only — never by the loop."""

    def __init__(self, model: RobotModel, host: str, port: int):
        super().__init__(model, 1.0 / model.foxglove.rate)
        self.host, self.port = host, port
        self.events: Any = self.queue(maxsize=1000)
        self.start_helper(
            "cdprctl-foxglove", "the Foxglove view", foxglove_main,
            model, self.snapshot.name, self.events, self.stop, self.ready, host, port,
        )  # fmt: skip

    def announcement(self) -> list[tuple[str, bool]]:
        """What ``cdprctl run`` says once the view serves: (line, to stderr)."""
        return [(f"foxglove: ws://{self.host}:{self.port} — the live 3D view (open it in "
                 "Foxglove: docs/foxglove.md)", False)]  # fmt: skip

    def event(self, t: float, text: str, kind: str = "event") -> None:
        if kind == "fault" and not text:  # a fault reset: the log says so in its own line
            return
        with contextlib.suppress(queue.Full):
            self.events.put_nowait((kind, t, text))

    def take_commands(self) -> list[Any]:
        """The view takes no commands."""
        return []
