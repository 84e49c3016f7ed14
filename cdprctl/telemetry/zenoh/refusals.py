"""Who Zenoh refused, in the daemon's own log: a refused login (wrong password, unknown user, a
certificate from another CA or none) and a command the access control dropped never reach the
gateway, so it cannot see them itself; Zenoh writes each one in its log (Zenoh 1.10: the
access control's per-message verdicts at TRACE, the logins at DEBUG, TLS at WARN). The gateway
of a secured configuration asks Zenoh for just those lines (``ZENOH_LOG_FILTER``), reads them
from a pipe and writes one line per refusal, rate-limited: the first of its kind at once, then
how many more every ``every`` s. A flood of refused commands is a handful of lines a minute.

Zenoh's text is parsed: an upgrade that changes it is caught by
tests/telemetry/zenoh/test_refusals.py (lines recorded from Zenoh 1.10.2) and the end-to-end ACL and
TLS tests of tests/telemetry/zenoh/test_zenoh.py."""

from __future__ import annotations

import math
import os
import re
import sys
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TextIO

#: the Zenoh log targets that say who was refused, and nothing else (RUST_LOG syntax)
ZENOH_LOG_FILTER = ",".join([
    "zenoh::net::routing::interceptor::access_control=trace",  # each message's verdict
    "zenoh_transport::unicast::establishment::accept=debug",  # "Invalid password.", ...
    "zenoh_link_tcp::unicast=debug",  # "Accepted TCP connection on L: REMOTE" (who logs in)
    "zenoh_link_tls::unicast=debug",  # a refused certificate; who logs in over TLS
])  # fmt: skip

_LINE = re.compile(
    r"^(?:\S+T(?P<h>\d\d):(?P<m>\d\d):(?P<s>\d\d(?:\.\d+)?)Z)?\s*(?P<level>TRACE|DEBUG|INFO|WARN|"
    r"ERROR)\s+(?:\S+\s+)?ThreadId\((?P<thread>\d+)\)\s+(?P<target>[\w:]+): (?P<text>.*)$"
)
_VERDICT = re.compile(
    r"^(?:Using cached result: )?(?P<zid>[0-9a-f]+)(?: on (?P<subject>\S+))? is "
    r"(?P<verdict>authorized|unauthorized) to (?P<action>[\w/ ]+) \(ingress\) on (?P<key>\S+)$"
)
_CACHING = re.compile(r"^ACL \(ingress\): caching permissions for `(?P<key>[^`]+)`")
_ACCEPTED = re.compile(r"^Accepted (?:TCP|TLS) connection on \S+: (?P<remote>\S+?)\.?(?: |$)")
_USRPWD = re.compile(r"^UsrPwd extension - Recv \w+\. (?P<why>.+?)\.?(?: at \S+\.rs:\d+\.?)?$")
_LOGIN = {
    "Invalid password": "wrong password",
    "Invalid user": "unknown user",
    "Expected extension": "no user and password given",
}
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
#: a verdict on each ACL subject a peer matches comes within this of the message's first (s)
SAME_MESSAGE = 0.001
#: a verdict still pending this long after it was read has no "authorized" to follow (s)
SETTLE = 0.05
#: distinct refusals kept for their counts; the oldest go first
KEPT = 256


@dataclass
class _Kind:
    """One kind of refusal (who, what): when it was last written, how many since; ``again``:
    the count's text (without the first peer's id: a user's every session counts)."""

    text: str
    again: str
    last_written: float
    since: int = 0


@dataclass
class _Pending:
    """An ACL refusal whose message may still be allowed by another of the peer's subjects."""

    log_time: float
    read_at: float
    who: str  # the user or certificate, and the peer
    ident: str  # the user or certificate alone (the peer when it has neither)
    action: str
    key: str


@dataclass
class Refusals:
    """Zenoh's log lines in (``feed``), cdprctl's lines on who was refused out (``emit``).

    ``prefix``: the robot's key prefix; ACL refusals count on ``<prefix>/...`` keys only.
    ``passthrough``: also emit every line as it came (the user set RUST_LOG)."""

    prefix: str
    emit: Callable[[str], None]
    every: float = 10.0
    passthrough: bool = False
    kinds: OrderedDict[tuple[str, ...], _Kind] = field(default_factory=OrderedDict)
    pending: dict[tuple[str, ...], _Pending] = field(default_factory=dict)
    who_is: dict[str, tuple[str, str]] = field(default_factory=dict)  # zid -> _who(...)
    remote: dict[str, str] = field(default_factory=dict)  # thread -> the peer it accepts
    caching: dict[str, str] = field(default_factory=dict)  # thread -> the key it evaluates
    next_tick: float = -math.inf  # the first line ticks

    def feed(self, raw: str, now: float) -> None:
        """One line of Zenoh's log, read at ``now`` (s, monotonic)."""
        line = _ANSI.sub("", raw).rstrip("\n")
        if self.passthrough and line:
            self.emit(line)
        if m := _LINE.match(line):
            self._parse(m, now)
        if now >= self.next_tick:
            self.tick(now)

    def tick(self, now: float) -> None:
        """Settles what is pending and writes the counts that are due (call it now and then)."""
        self.next_tick = now + SETTLE
        for k, p in list(self.pending.items()):
            if now - p.read_at >= SETTLE:
                del self.pending[k]
                self._acl_refused(p, now)
        for kind in self.kinds.values():
            if kind.since and now - kind.last_written >= self.every:
                n = kind.since
                self.emit(f"cdprctl-zenoh: {kind.again} (again, {n} more "
                          f"time{'s' if n > 1 else ''} in the last {self.every:g} s)")  # fmt: skip
                kind.last_written, kind.since = now, 0

    def _parse(self, m: re.Match[str], now: float) -> None:
        target, text, thread = m["target"], m["text"], m["thread"]
        log_time = (int(m["h"]) * 3600 + int(m["m"]) * 60 + float(m["s"])) if m["h"] else now
        if target.endswith("access_control"):
            if c := _CACHING.match(text):
                self.caching[thread] = c["key"]
            elif v := _VERDICT.match(text):
                self._verdict(v, thread, log_time, now)
        elif target.startswith(("zenoh_link_tcp", "zenoh_link_tls")):
            if a := _ACCEPTED.match(text):
                self.remote[thread] = a["remote"]
            elif m["level"] == "WARN" and target.startswith("zenoh_link_tls"):
                why = text.split(". Hint:")[0].rstrip(".")  # its hint is about file limits
                if "handshake eof" not in why:  # closed before its handshake: a port probe
                    self._refused(("tls", why), f"refused a TLS connection: {why}{_tls(why)}",
                                  now)  # fmt: skip
        elif target.endswith("establishment::accept") and (u := _USRPWD.match(text)):
            who = self.remote.get(thread, "an unknown address")
            host = who.rsplit(":", 1)[0] if ":" in who else who
            why = _LOGIN.get(u["why"], u["why"])
            self._refused(("login", host, why), f"refused a login from {host}: {why}", now)

    def _verdict(self, v: re.Match[str], thread: str, log_time: float, now: float) -> None:
        zid, key, action = v["zid"], v["key"], v["action"].lower()
        if v["subject"]:
            self.who_is[zid] = _who(v["subject"], zid)
        if self.caching.get(thread) == key:
            return  # the permissions cached for a declaration on that key: no message
        self.caching.pop(thread, None)
        if not key.startswith(self.prefix + "/"):
            return  # another robot's
        k = (thread, zid, action, key)
        if v["verdict"] == "authorized":
            self.pending.pop(k, None)  # another of the peer's subjects allows it
            return
        p = self.pending.get(k)
        if p is not None and abs(log_time - p.log_time) < SAME_MESSAGE:
            return  # the same message judged for another subject
        if p is not None:
            self._acl_refused(p, now)
        who, ident = self.who_is.get(zid, (f"peer {zid[:8]}", f"peer {zid[:8]}"))
        self.pending[k] = _Pending(log_time, now, who, ident, action, key)

    def _acl_refused(self, p: _Pending, now: float) -> None:
        """One refusal of the kind (user or certificate, what, where): a user's sessions
        count together (every ``cdprctl send`` is a new peer)."""
        what = f"may not {p.action} {p.key}"
        self._refused(("acl", p.ident, p.action, p.key),
                      f"refused by the access control: {p.who} {what}", now,
                      f"refused by the access control: {p.ident} {what}")  # fmt: skip

    def _refused(self, key: tuple[str, ...], text: str, now: float, again: str = "") -> None:
        kind = self.kinds.get(key)
        if kind is not None:
            kind.since += 1
            self.kinds.move_to_end(key)
            return
        self.kinds[key] = _Kind(text, again or text, now)
        if len(self.kinds) > KEPT:
            self.kinds.popitem(last=False)
        self.emit(f"cdprctl-zenoh: {text}")


def _who(subject: str, zid: str) -> tuple[str, str]:
    """``Interface(lo)+Username(viewer)+Transport(Tcp)+<zid>`` → (``user viewer (peer
    3daf7a81 on lo)``, ``user viewer``); a certificate's common name likewise; a peer with
    neither: the peer, twice."""
    parts = dict(re.findall(r"(\w+)\(([^)]*)\)", subject))
    where = f"peer {zid[:8]}" + (f" on {parts['Interface']}" if "Interface" in parts else "")
    if "Username" in parts:
        ident = f"user {parts['Username']}"
    elif "CertCommonName" in parts:
        ident = f"certificate {parts['CertCommonName']}"
    else:
        return where, where
    return f"{ident} ({where})", ident


def _tls(why: str) -> str:
    if "BadSignature" in why or "UnknownIssuer" in why:
        return " (a certificate this robot's CA did not sign)"
    if "no certificates" in why:
        return " (a client without a certificate)"
    if "UnknownCA" in why:
        return (" (the client does not trust this robot's certificate: its "
                "root_ca_certificate is not this robot's CA)")  # fmt: skip
    return ""


def refuses_anybody(config_file: str) -> bool:
    """Whether a Zenoh configuration file refuses anybody: authentication or access control
    (a file Zenoh cannot read refuses nobody here: the session's opening says why)."""
    import zenoh

    from cdprctl.telemetry.zenoh.security import config_value

    try:
        conf = zenoh.Config.from_file(config_file)
    except Exception:
        return False
    usrpwd = config_value(conf, "transport/auth/usrpwd") or {}
    tls = config_value(conf, "transport/link/tls") or {}
    acl = config_value(conf, "access_control") or {}
    return bool(usrpwd.get("dictionary_file") or tls.get("enable_mtls") or acl.get("enabled"))


def log_refusals(prefix: str, err: TextIO = sys.stderr) -> Refusals:
    """Starts Zenoh's log into a pipe read by a daemon thread (call before opening the
    session, once per process): ``Refusals`` lines on ``err``; with RUST_LOG set, the filter is
    the user's and Zenoh's lines go on to the process's stdout as before."""
    import time

    import zenoh

    user_asked = bool(os.environ.get("RUST_LOG"))
    os.environ.setdefault("NO_COLOR", "1")
    read_fd, write_fd = os.pipe()
    try:
        import fcntl

        fcntl.fcntl(write_fd, 1031, 1 << 20)  # F_SETPIPE_SZ: 1 MiB before Zenoh would block
    except OSError:
        pass
    stdout = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(write_fd, 1)  # Zenoh writes its log on stdout
    os.close(write_fd)
    sys.stdout = stdout  # Python's own prints keep their place

    def emit_out(line: str) -> None:
        (err if line.startswith("cdprctl-zenoh:") else stdout).write(line + "\n")
        err.flush()

    refusals = Refusals(prefix, emit_out, passthrough=user_asked)
    lock = threading.Lock()

    def read() -> None:
        import select

        buf = b""
        with os.fdopen(read_fd, "rb", buffering=0) as pipe:
            while True:
                ready, _, _ = select.select([pipe], [], [], 0.2)
                now = time.monotonic()
                with lock:
                    if not ready:
                        refusals.tick(now)
                        continue
                    chunk = pipe.read(65536)
                    if not chunk:
                        return
                    buf += chunk
                    *lines, buf = buf.split(b"\n")
                    for raw in lines:
                        refusals.feed(raw.decode("utf-8", "replace"), now)

    threading.Thread(target=read, name="cdprctl-zenoh-log", daemon=True).start()
    if user_asked:
        zenoh.try_init_log_from_env()
    else:
        zenoh.init_log_from_env_or(ZENOH_LOG_FILTER)
    return refusals
