"""Whether the drives a command reaches are a simulated robot's: a simulation never writes
where a real robot's records live, and a real robot never takes a simulated robot's record
(cdprctl/core/state_dir.py)."""

from __future__ import annotations

from typing import Any

from cdprctl.model.robot import RobotModel
from drivers.buses import bus_medium

# python-can's media that reach no wire: only a simulated robot answers on them
SIMULATED_MEDIA = frozenset({"virtual", "udp_multicast", "inprocess", "socketpair"})
# of them, what a robot file names and no other process reaches: python-can's virtual bus
# (cdprctl's lock-step "inprocess" one is the tests' harness: the canopen package's nodes in
# the same process answer there)
IN_PROCESS_MEDIA = frozenset({"virtual"})
# the simulated drives' 0x1018 serial number: node id + 'SIM\0' (sim_backend/drives/*.eds)
SIMULATED_SERIAL = 0x53494D00


def simulated_identities(identities: list[Any]) -> bool:
    """Every drive answered 0x1018 as a simulated drive does (vendor 0, serial 'SIM' + node)."""
    return bool(identities) and all(
        isinstance(i, dict) and i.get("vendor_id") == 0
        and (int(i.get("serial", 0)) & 0xFFFFFF00) == SIMULATED_SERIAL
        for i in identities
    )  # fmt: skip


def in_process_only(model: RobotModel, overrides: dict[str, Any]) -> bool:
    """Every bus of ``model`` (after ``overrides``) is one no other process can reach: nothing
    but a simulated robot built in this very process (``--sim``) can answer there."""
    media = {bus_medium(b, overrides, i)[0] for i, b in enumerate(model.drives.buses)}
    return bool(media) and media <= IN_PROCESS_MEDIA


def simulated_robot(model: RobotModel, overrides: dict[str, Any], driver: Any = None) -> bool:
    """Whether the drives of ``model`` (on the buses ``overrides`` give) are a simulated
    robot's: every bus on a medium no wire reaches, or, once ``driver`` is configured, every
    drive identifying itself as simulated (a simulated robot behind a kernel vcan, as in HIL)."""
    media = {bus_medium(b, overrides, i)[0] for i, b in enumerate(model.drives.buses)}
    if media and media <= SIMULATED_MEDIA:
        return True
    return simulated_identities(list(getattr(driver, "identities", None) or []))
