"""``cdprctl jog``: move a robot by hand from a terminal, over Zenoh (``cmd/jog``)."""

from __future__ import annotations

import argparse
import json
import os
import select
import shutil
import sys
import termios
import textwrap
import threading
import time
import tty
from typing import Any

from cdprctl.commands.parsing import command_parser
from cdprctl.commands.zenoh_session import (
    add_zenoh_arguments,
    key_prefix,
    robot_status,
    tool_session,
    why_no_answer,
)

# key → (coordinate, sign): x y z (m/s), roll pitch yaw (rad/s about the frame's axes)
KEYS = {
    "d": (0, 1), "a": (0, -1),
    "w": (1, 1), "s": (1, -1),
    "e": (2, 1), "q": (2, -1),
    "l": (3, 1), "j": (3, -1),
    "i": (4, 1), "k": (4, -1),
    "o": (5, 1), "u": (5, -1),
}  # fmt: skip
SPEEDS = (0.01, 0.05, 0.1, 0.25, 0.5, 1.0)  # fractions of the configured velocity limits
# A terminal sends no key-up: a held key repeats after ~0.25-0.66 s, then 25-30 times/s. A
# first press holds for HOLD_FIRST (the repeat delay); once repeats come, a key counts as held
# while they keep coming within HOLD: let go, and the jog ends (a zero jog) that soon.
HOLD_FIRST = 0.7  # s
HOLD = 0.15  # s
REPEAT = 0.1  # s: key events closer than this are a held key's repeats
SEND_EVERY = 0.05  # s: well inside the daemon's deadman (default 0.2 s)
NO_REPLY = 2.0  # s: a daemon answers a command within a cycle or two; none by then is news

HELP = """\
keys (hold to move; a terminal repeats a held key after ~0.5 s, so a tap moves a bit):
  d/a +x/-x   w/s +y/-y   e/q +z/-z   l/j +roll/-roll   i/k +pitch/-pitch   o/u +yaw/-yaw
  +/- speed step   f frame base/platform   space stop   E enable   D disable   R reset   x quit"""


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "jog", "move a robot by hand from this terminal", jog, config=False)
    p.add_argument("--speed", type=int, default=2, choices=range(len(SPEEDS)),
                   help="start at this step of " + ", ".join(f"{s * 100:g}%%" for s in SPEEDS)
                   + " of the configured limits (default 2)")  # fmt: skip
    p.add_argument("--frame", choices=("base", "platform"), default="base")
    add_zenoh_arguments(p)


class Jogger:
    """The tool's state; ``key`` takes a key, ``tick`` sends what is due."""

    def __init__(self, session: Any, prefix: str, limits: dict[str, float], speed: int,
                 frame: str):  # fmt: skip
        self.session, self.prefix = session, prefix
        self.vmax = float(limits.get("max_velocity", 0.1))
        self.wmax = float(limits.get("max_angular_velocity", 0.1))
        self.speed, self.frame = speed, frame
        self.axis: tuple[int, int] | None = None
        self.last_key = 0.0
        self.repeating = False
        self.last_send = 0.0
        self.moving = False
        self.note = ""
        self.quit = False
        self.state = ""  # the robot's, as last received
        self._ids = 0
        self.awaiting: tuple[str, float] | None = None  # the oldest unanswered: kind, sent s

    def put(self, kind: str, payload: dict[str, Any] | None = None) -> None:
        """A command with this tool's id (the jogs one id for all), so its reply is shown and
        its absence noticed (``unanswered``)."""
        body = dict(payload or {})
        if kind == "jog":
            body["id"] = "jog-tool-jog"
        else:
            self._ids += 1
            body["id"] = f"jog-tool-{self._ids}"
        if self.awaiting is None:
            self.awaiting = (kind, time.monotonic())
        self.session.put(f"{self.prefix}/cmd/{kind}", json.dumps(body))

    def unanswered(self, now: float, replied: bool) -> str:
        """The kind of the oldest command sent since the last reply if it has waited
        ``NO_REPLY`` s (then forgotten), else "" (``replied``: a reply came since the last
        call) — a viewer's held jog key as much as its enable."""
        if self.awaiting is None or replied:
            self.awaiting = None
            return ""
        kind, sent = self.awaiting
        if now - sent <= NO_REPLY:
            return ""
        self.awaiting = None
        return kind

    def can_jog(self) -> bool:
        """Jogs are taken in enabled and moving only: elsewhere each would be refused (a held
        key, a dozen refusals in the daemon's log) — say so here instead."""
        if self.state in ("enabled", "moving"):
            return True
        self.note = f"jog: the robot is {self.state or 'not heard from yet'} (E enables it)"
        return False

    def velocity(self) -> list[float]:
        v = [0.0] * 6
        if self.axis is not None:
            k, sign = self.axis
            v[k] = sign * SPEEDS[self.speed] * (self.vmax if k < 3 else self.wmax)
        return v

    def key(self, ch: str, now: float) -> None:
        if ch in KEYS:
            if not self.can_jog():
                return
            if self.axis != KEYS[ch]:
                self.axis = KEYS[ch]
                self.last_send = 0.0  # a new direction goes out at once
                self.repeating = False
            else:
                self.repeating = now - self.last_key < REPEAT
            self.last_key = now
        elif ch == " ":
            self.axis = None
            self.put("jog", {"velocity": [0.0] * 6, "frame": self.frame})
            self.put("stop")
            self.moving = False
            self.note = "stop"
        elif ch in "+=":
            self.speed = min(len(SPEEDS) - 1, self.speed + 1)
        elif ch == "-":
            self.speed = max(0, self.speed - 1)
        elif ch == "f":
            self.frame = "platform" if self.frame == "base" else "base"
        elif ch in "EDR":
            kind = {"E": "enable", "D": "disable", "R": "reset"}[ch]
            self.put(kind)
            self.note = f"{kind}: sent"
        elif ch in ("x", "\x03", "\x04"):
            self.quit = True

    def tick(self, now: float) -> None:
        hold = HOLD if self.repeating else HOLD_FIRST
        held = self.axis is not None and now - self.last_key < hold
        if held and now - self.last_send >= SEND_EVERY:
            self.put("jog", {"velocity": self.velocity(), "frame": self.frame})
            self.last_send, self.moving = now, True
        elif not held and self.moving:  # let go: stop now, not at the deadman
            self.axis = None
            self.put("jog", {"velocity": [0.0] * 6, "frame": self.frame})
            self.moving = False


def _view(j: Jogger, state: dict[str, Any] | None, prefix: str) -> str:
    names = ("+x", "+y", "+z", "+roll", "+pitch", "+yaw")
    moving = "-"
    if j.axis is not None and j.moving:
        k, sign = j.axis
        moving = ("-" if sign < 0 else "+") + names[k][1:]
    lines = [f"cdprctl jog {prefix}   speed {SPEEDS[j.speed]:.0%} of the limits "
             f"({SPEEDS[j.speed] * j.vmax:.3g} m/s, {SPEEDS[j.speed] * j.wmax:.3g} rad/s)   "
             f"frame {j.frame}   jogging {moving}"]  # fmt: skip
    if state is None:
        lines.append("waiting for the robot's state ...")
    else:
        p, rpy = state["pose"]["position"], state["pose"]["rpy"]
        lines.append(f"state {state['state']:<9} position [{p[0]:.4f} {p[1]:.4f} {p[2]:.4f}] m"
                     f"  rpy [{rpy[0]:.4f} {rpy[1]:.4f} {rpy[2]:.4f}] rad"
                     f"  motion {state.get('motion') or '-'}")  # fmt: skip
        if state.get("fault"):
            lines.append(f"fault: {state['fault']}")
    if j.note:  # wrapped at words to the terminal (the terminal's own wrap cut them)
        width = shutil.get_terminal_size((100, 24)).columns - 1
        lines += textwrap.wrap(j.note, max(40, width), subsequent_indent="  ")
    lines.append(HELP)
    return "\x1b[H\x1b[2J" + "\r\n".join(x.replace("\n", "\r\n") for x in lines)


class Inbox:
    """What the daemon said since the screen was last drawn, from Zenoh's threads: its last
    state, the note to show (a reply, or its word on a jog or a fault), whether one of our
    jogs was answered."""

    def __init__(self) -> None:
        self.latest: dict[str, Any] = {}
        self.lock = threading.Lock()

    def take(self) -> tuple[str | None, dict[str, Any] | None, bool]:
        """(the note, or None: none new; the last state; whether a jog of ours was answered
        since the last take)."""
        with self.lock:
            return (self.latest.pop("note", None), self.latest.get("state"),
                    bool(self.latest.pop("replied", False)))  # fmt: skip

    def on_state(self, sample: Any) -> None:
        try:
            with self.lock:
                self.latest["state"] = json.loads(sample.payload.to_bytes())
        except ValueError:
            pass

    def on_reply(self, sample: Any) -> None:
        try:
            body = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        kind = str(sample.key_expr).rsplit("/", 1)[-1]
        ours = str(body.get("id") or "").startswith("jog-tool-")
        if not ours and body.get("ok"):
            return  # another client's
        with self.lock:
            self.latest["replied"] = self.latest.get("replied", False) or ours
            if not (kind == "jog" and body.get("ok")):  # not 20 "accepted" a second
                self.latest["note"] = (f"{kind}: accepted" if body.get("ok")
                                       else f"{kind}: rejected: {body.get('reason')}")  # fmt: skip

    def on_event(self, sample: Any) -> None:
        """The daemon's word on a jog (where the soft limits stop it, and why) or a fault."""
        try:
            text = str(json.loads(sample.payload.to_bytes()).get("text", ""))
        except ValueError:
            return
        if text.startswith(("jog", "FAULT")):
            with self.lock:
                self.latest["note"] = text


def jog(args: argparse.Namespace) -> int:
    """Move the robot with the keyboard: each held key is a velocity (a fraction of the
    configured limits) sent as cmd/jog every 50 ms; the daemon stops at the soft limits and
    when the jogs stop coming (its deadman). Needs the daemon to accept commands
    (docs/telemetry.md) and a terminal."""
    prefix = key_prefix(args)
    if prefix is None:
        return 2
    if not os.isatty(sys.stdin.fileno()):
        print("cdprctl jog: error: needs a terminal (stdin is not a tty)", file=sys.stderr)
        return 2
    session = tool_session(args)
    if session is None:
        return 2
    inbox = Inbox()
    subs = [session.declare_subscriber(f"{prefix}/state", inbox.on_state),
            session.declare_subscriber(f"{prefix}/reply/*", inbox.on_reply),
            session.declare_subscriber(f"{prefix}/events", inbox.on_event)]  # fmt: skip
    status = robot_status(session, prefix)
    if not status:  # nothing to jog: say why before the screen takes the terminal
        why = why_no_answer(session, args, prefix, command=False)
        for sub in subs:
            sub.undeclare()
        session.close()
        print(f"cdprctl jog: {why}", file=sys.stderr)
        return 2
    limits = status.get("config", {}).get("limits", {})
    j = Jogger(session, prefix, limits, args.speed, args.frame)
    if not limits:
        j.note = f"no limits in {prefix}'s status: guessed (0.1 m/s, 0.1 rad/s)"
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    next_draw = 0.0
    try:
        tty.setcbreak(fd)
        while not j.quit:
            ready, _, _ = select.select([fd], [], [], 0.02)
            now = time.monotonic()
            if ready:
                for ch in os.read(fd, 64).decode(errors="ignore"):
                    j.key(ch, now)
            j.tick(now)
            if now >= next_draw:
                note, state, replied = inbox.take()
                if note is not None:
                    j.note = note
                lost = j.unanswered(now, replied)
                if lost:  # a command the gateway dropped: say why
                    why = why_no_answer(session, args, prefix)
                    j.note = f"{lost}: no reply in {NO_REPLY:g} s: {why}"
                j.state = str(state.get("state", "")) if state else ""
                sys.stdout.write(_view(j, state, prefix))
                sys.stdout.flush()
                next_draw = now + 0.1
    except KeyboardInterrupt:
        pass
    finally:
        try:
            j.put("jog", {"velocity": [0.0] * 6, "frame": j.frame})
        finally:
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)
            for s in subs:
                s.undeclare()
            session.close()
            print()
    return 0
