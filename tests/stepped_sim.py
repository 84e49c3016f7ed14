"""A simulated robot stepped in real time by a thread (1 ms steps) while a test's independent
CANopen master (the ``canopen`` package) talks to it over the in-process bus; the tests of the
simulated drives and load cells share it (tests/sim_backend/)."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from cdprctl.model.robot import RobotModel
from sim_backend.network import SimNetwork
from sim_backend.plant import CdprPlant


class SteppedSim:
    """``model``'s simulated robot on ``bus_overrides``; ``lock`` is held while it steps."""

    def __init__(self, model: RobotModel, bus_overrides: dict[str, Any],
                 plant: CdprPlant | None = None):  # fmt: skip
        self.model = model
        self.plant = plant if plant is not None else CdprPlant(model)
        self.net = SimNetwork(model, self.plant, bus_overrides)
        # a step before the thread: the physics kernels compile at their first call (seconds
        # on a cold cache, the drives deaf meanwhile: the scanner found none in 3 s in a
        # mutation session's fresh tree)
        self.net.advance(0.001)
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            with self.lock:
                self.net.advance(0.001)
            time.sleep(0.001)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.net.close()


@contextlib.contextmanager
def master_of(robot: Any, channel: str, eds: Path,
              node_ids: Iterable[int]) -> Iterator[tuple[Any, Any, dict[int, Any]]]:  # fmt: skip
    """(robot, the ``canopen`` master on ``channel``, its node per id read from ``eds``); the
    master disconnected and the robot closed after."""
    from conftest import canopen_network

    network = canopen_network()
    network.connect(interface="inprocess", channel=channel)
    nodes = {n: network.add_node(n, str(eds)) for n in node_ids}
    for node in nodes.values():
        node.sdo.RESPONSE_TIMEOUT = 1.0  # generous: a loaded machine
    try:
        yield robot, network, nodes
    finally:
        network.disconnect()
        robot.close()
