"""Whom the gateway's Zenoh session reached, from the session's own information (``info``:
routers, peers, links): the line the daemon says at start-up, and the ``zenoh`` part of the
status by which ``cdprctl robots`` lists a fleet (docs/fleet.md)."""

from __future__ import annotations

from typing import Any

from cdprctl.model.zenoh import ZenohConfig


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


def connection_line(session: Any, zc: ZenohConfig) -> str:
    """``zenoh: connected to tcp/10.0.0.1:7447: 1 router, 0 peers``, or why nobody is reached
    yet, with where this gateway listens; one line."""
    info = session.info
    routers, peers = len(info.routers_zid()), len(info.peers_zid())
    listening = f"listening on {', '.join(zc.listen)}" if zc.listen else "no listen endpoint"
    if routers or peers:
        ends = sorted({str(link.dst) for link in info.links()} & set(zc.connect)) or sorted(
            str(link.dst) for link in info.links()
        )
        return (f"zenoh: connected to {', '.join(ends) or 'a peer'}: {_count(routers, 'router')}, "
                f"{_count(peers, 'peer')} ({listening})")  # fmt: skip
    if zc.connect:
        return (f"zenoh: no router/peer reached at {', '.join(zc.connect)} ({listening}; the "
                "session keeps trying: check the router runs and the address)")  # fmt: skip
    scouting = "multicast scouting on" if zc.multicast_scouting else "no multicast scouting"
    return (f"zenoh: no router/peer reached (no connect endpoint, {scouting}; {listening}): "
            "tools reach this robot with --connect at its listen endpoint")  # fmt: skip


def identity(session: Any, zc: ZenohConfig) -> dict[str, Any]:
    """What the status says of the gateway's place on the network: its Zenoh id, mode and
    endpoints (``cdprctl robots``)."""
    return {
        "zid": str(session.info.zid()),
        "mode": zc.mode,
        "listen": list(zc.listen),
        "connect": list(zc.connect),
    }
