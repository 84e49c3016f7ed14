"""The state machine: the one object that changes ``ControlData.state``.

The command desk (an operator's enable, disable, stop, reset, move, jog, path), the supervisor
(the drives on, a fault, a stop done, a target reached) and the start-up (the pose found) ask
for a state with ``request``; the machine alone decides, by its table (``TRANSITIONS``: a
transition not in it is refused with an event), writes the state, notes when it was entered,
and forgets what the supervised checks had seen held once the state is no longer supervised.
A request is acted on at once, in the order asked, so a state set by a command early in a
cycle is the one the supervisor checks later in the same cycle.
``tests/control/supervision/test_state_owner.py`` holds that no other module writes the state.
"""

from __future__ import annotations

from typing import Protocol

from cdprctl.control.data import ControlData
from cdprctl.control.states import DISABLING, ENABLED, MOVING, STOPPING, State

S = State
#: every transition the machine makes; a transition missing here is refused (an event)
TRANSITIONS: dict[State, frozenset[State]] = {
    S.INIT: frozenset({S.READY, S.FAULT}),
    S.READY: frozenset({S.ENABLING, S.STOPPING, S.FAULT}),
    S.ENABLING: frozenset({S.ENABLED, S.DISABLING, S.READY, S.STOPPING, S.FAULT}),
    S.ENABLED: frozenset({S.ENABLED, S.MOVING, S.DISABLING, S.READY, S.STOPPING, S.FAULT}),
    S.MOVING: frozenset({S.MOVING, S.ENABLED, S.DISABLING, S.READY, S.STOPPING, S.FAULT}),
    S.DISABLING: frozenset({S.READY, S.STOPPING, S.FAULT}),
    S.STOPPING: frozenset({S.FAULT, S.ENABLED, S.DISABLING}),
    S.FAULT: frozenset({S.READY}),
    S.ESTOP: frozenset({S.READY}),
}
# the safety chain can open in any state but the start-up's (the drives not yet configured)
for _s in (S.READY, S.ENABLING, S.ENABLED, S.MOVING, S.DISABLING, S.STOPPING, S.FAULT):
    TRANSITIONS[_s] = TRANSITIONS[_s] | {S.ESTOP}

#: the states the supervisor watches; leaving them, what its checks saw held is forgotten
SUPERVISED = (ENABLED, MOVING, DISABLING, STOPPING)


class Forgettable(Protocol):
    """What held before: ``held(t, False)`` forgets it (``persistence.Persistence``)."""

    def held(self, t: float, on: bool, weight: float = 1.0) -> bool: ...


class StateMachine:
    def __init__(self, data: ControlData):
        self.data = data
        self.entered = 0.0  # s, when the state was entered
        # the supervised checks' persistences (Supervisor): forgotten out of SUPERVISED
        self._forget: tuple[Forgettable, ...] = ()

    @property
    def state(self) -> State:
        return self.data.state

    def forget_when_unsupervised(self, persistences: tuple[Forgettable, ...]) -> None:
        """``persistences`` start anew each time the state leaves ``SUPERVISED``."""
        self._forget = self._forget + persistences

    def request(self, s: State, t: float, why: str) -> bool:
        """State ``s`` from time ``t`` (s) for ``why`` (the event's text), if ``TRANSITIONS``
        allows it from the state now; False (and an event) when refused."""
        d = self.data
        if s not in TRANSITIONS[d.state]:
            d.events.append((t, f"internal: transition {d.state.value} -> {s.value} refused"))
            return False
        if s is not d.state:
            d.events.append((t, f"state {d.state.value} -> {s.value}: {why}"))
        if s not in SUPERVISED:
            # unsupervised from here on: what held before must persist anew once enabled (a
            # drive at its limit before a fault tripped the check at the next enable at once)
            for p in self._forget:
                p.held(t, False)
        d.state = s
        self.entered = t
        return True
