"""The ``[foxglove]`` section: the live 3D view's WebSocket server (``cdprctl run --foxglove``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cdprctl.model.reader import Number, TableReader, read_fields, read_section

FOXGLOVE_KEYS = ("listen", "rate")


@dataclass(frozen=True)
class FoxgloveConfig:
    # HOST:PORT (or PORT: on 127.0.0.1) of the WebSocket server; "" = no server. Anyone who
    # reaches it sees the robot (it takes no commands): bind beyond localhost on purpose only
    listen: str = ""
    rate: float = 30.0  # Hz, the scene's rate (decimated from the loop, never in it)

    @property
    def enabled(self) -> bool:
        return bool(self.listen)


def parse_listen(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` → (host, port); the host defaults to 127.0.0.1. ValueError naming the
    rule."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 < number < 65536:
        raise ValueError(f"{text!r} must be [HOST:]PORT with PORT in 1..65535")
    return (host.strip("[]") or "127.0.0.1"), number


def read_foxglove(rd: TableReader, data: dict[str, Any]) -> FoxgloveConfig | None:
    def read(t: dict[str, Any], vals: dict[str, Any]) -> None:
        listen = rd.string(t, "listen", "foxglove", required=False, default="")
        if listen:
            try:
                parse_listen(listen)
                vals["listen"] = listen
            except ValueError as exc:
                rd.error("foxglove.listen", listen, "", str(exc).split(" ", 1)[1])
        rate = Number("rate", "Hz", positive=True, maximum=200.0)
        read_fields(rd, t, "foxglove", (rate,), FoxgloveConfig(), vals)

    return read_section(rd, data, "foxglove", FOXGLOVE_KEYS, FoxgloveConfig, read)
