"""The daemon's links to the world beside the loop — the Zenoh gateway, the Foxglove view and
those to come — as one fan-out: each is a process fed by a shared-memory snapshot; they are
started, fed the same values and events, asked for commands and closed together, by the I/O
thread only (never the loop)."""

from __future__ import annotations

from typing import Any, Protocol

from cdprctl.control.command_types import Command
from cdprctl.control.data import ControlData
from cdprctl.model.robot import RobotModel
from cdprctl.telemetry.helper import HelperProcess
from cdprctl.telemetry.snapshot import controller_values


class Link(Protocol):
    """What the daemon asks of a link (``telemetry.helper.SnapshotLink``'s: the gateway's
    ``TelemetryLink``, ``FoxgloveLink``, ``Ros2Link``)."""

    period: float  # s between the values it wants
    helper: HelperProcess  # its process: started by ``Links.start``

    def announcement(self) -> list[tuple[str, bool]]: ...  # (line, to stderr) once started
    def due(self) -> bool: ...
    def write(self, values: dict[str, Any], stats: Any) -> None: ...
    def event(self, t: float, text: str, kind: str = "event") -> None: ...
    def take_commands(self) -> list[Command]: ...
    def close(self) -> None: ...


def links_of(model: RobotModel, zenoh: bool, foxglove: str | None, summary: Any,
             ros2: bool = False) -> list[Link]:  # fmt: skip
    """The links the configuration and the command line ask for; ``summary()`` gives the
    configuration summary the gateway serves."""
    out: list[Link] = []
    if zenoh or model.zenoh.enabled:
        from cdprctl.telemetry.zenoh.link import TelemetryLink

        out.append(TelemetryLink(model, summary()))
    listen = foxglove or model.foxglove.listen
    if listen:
        from cdprctl.model.foxglove import parse_listen
        from cdprctl.telemetry.foxglove.foxglove_view import FoxgloveLink

        out.append(FoxgloveLink(model, *parse_listen(listen)))
    if ros2 or model.ros2.enabled:
        from cdprctl.telemetry.ros2.ros2_view import Ros2Link

        out.append(Ros2Link(model))
    return out


class Links:
    def __init__(self, links: list[Link]):
        self.links = links
        # s: how often the I/O thread must wake for them (at least 20 Hz for the status line)
        self.tick = min([0.05, *(x.period for x in links)])

    def __bool__(self) -> bool:
        return bool(self.links)

    def start(self) -> str:
        """Start every link; "" when all did, else what failed (every link closed)."""
        for link in self.links:
            if not link.helper.start(timeout=20.0):
                self.close()
                return link.helper.failure
        return ""

    def publish(self, data: ControlData, stats: Any, true_position: Any) -> None:
        """The loop's values, taken once, to every link whose period has come."""
        due = [x for x in self.links if x.due()]
        if due:
            values = controller_values(data, true_position)
            for link in due:
                link.write(values, stats)

    def event(self, t: float, text: str, kind: str = "event") -> None:
        for link in self.links:
            link.event(t, text, kind)

    def take_commands(self) -> list[Command]:
        return [cmd for link in self.links for cmd in link.take_commands()]

    def close(self) -> None:
        """Close every link; safe twice (a failed start closes them, the exit again)."""
        links, self.links = self.links, []
        for link in links:
            link.close()
