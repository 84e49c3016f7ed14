"""Commands fail closed: the daemon takes commands over Zenoh only when its Zenoh configuration
authenticates every peer and denies by default (docs/telemetry.md, "Security").

Read with Zenoh's own parser (``zenoh.Config.from_file`` and ``get_json``), so what is checked
is what the session will use. Authentication: user/password (``transport.auth.usrpwd`` with
``dictionary_file``), or mutual TLS (``transport.link.tls.enable_mtls`` with a
``root_ca_certificate``) with every listen endpoint on ``tls/`` (a ``tcp/`` one would let
anybody in). Access control: ``access_control.enabled`` with ``default_permission = "deny"``.
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the tools import this module: the robot model (numpy) only for the daemon
    from cdprctl.model.zenoh import ZenohConfig

EXAMPLE = "config/zenoh/gateway-acl.json5 (user/password) or config/zenoh/gateway-tls.json5"
BENCH = (
    "or, on an isolated bench network only, set [zenoh] allow_unauthenticated_commands = true "
    "(cdprctl run --allow-unauthenticated-commands)"
)
UNAUTHENTICATED_WARNING = (
    "commands are accepted from unauthenticated peers (allow_unauthenticated_commands): "
    "anybody on the network can move the robot"
)


def config_value(conf: Any, key: str) -> Any:
    """The value at ``key`` (``a/b/c``) of a ``zenoh.Config``, None when absent."""
    try:
        return json.loads(conf.get_json(key))
    except Exception:  # absent keys raise in zenoh's binding
        return None


def command_security_problems(zc: ZenohConfig) -> list[str]:
    """Why commands may not be taken with ``zc`` (empty: they may). Each names the key and what
    to add."""
    if not zc.commands or zc.allow_unauthenticated_commands:
        return []
    if not zc.config_file:
        return [
            "zenoh: commands are enabled ([zenoh] commands = true or --accept-commands) with no "
            "Zenoh configuration: set [zenoh] config_file (or --zenoh-config) to a file that "
            f"authenticates peers and denies by default, such as {EXAMPLE}; {BENCH}"
        ]
    import zenoh

    try:
        conf = zenoh.Config.from_file(zc.config_file)
    except Exception as exc:
        why = zenoh_error(exc)
        return [f"zenoh.config_file = {zc.config_file}: not a Zenoh configuration ({why})"]
    problems = []
    usrpwd = config_value(conf, "transport/auth/usrpwd") or {}
    tls = config_value(conf, "transport/link/tls") or {}
    endpoints = list(zc.listen) or config_value(conf, "listen/endpoints") or []
    if isinstance(endpoints, dict):  # per mode ({peer: [...], router: [...]}): every one
        endpoints = [e for v in endpoints.values() for e in (v or [])]
    listen = list(endpoints)
    by_password = bool(usrpwd.get("user") and usrpwd.get("dictionary_file"))
    by_mtls = bool(tls.get("enable_mtls") and tls.get("root_ca_certificate"))
    plain = [e for e in listen if not str(e).startswith(("tls/", "quic/"))]
    if not by_password and not (by_mtls and not plain):
        problems.append(
            f"zenoh.config_file = {zc.config_file}: peers are not authenticated: add "
            "transport.auth.usrpwd (user, password, dictionary_file) or mutual TLS "
            "(transport.link.tls.enable_mtls = true with root_ca_certificate, and listen only "
            "on tls/ endpoints"
            + (f"; {', '.join(map(str, plain))} is not" if by_mtls and plain else "")
            + f"), as in {EXAMPLE}; {BENCH}"
        )
    acl = config_value(conf, "access_control") or {}
    if not acl.get("enabled"):
        problems.append(
            f"zenoh.config_file = {zc.config_file}: access_control.enabled is not true: every "
            f"authenticated peer could command; add an ACL that denies by default, as in "
            f"{EXAMPLE}; {BENCH}"
        )
    elif str(acl.get("default_permission", "deny")) != "deny":
        problems.append(
            f"zenoh.config_file = {zc.config_file}: access_control.default_permission = "
            f'{acl.get("default_permission")!r} must be "deny": with "allow" any account '
            f"not named in a deny rule can command; allow cdpr/*/cmd/** puts to the operator "
            f"only, as in {EXAMPLE}; {BENCH}"
        )
    return problems


def zenoh_error(exc: BaseException) -> str:
    """A Zenoh error's message without the Rust source location it ends with (`` at
    /root/.cargo/...rs:1486.``) and on one line."""
    text = " ".join(str(exc).split())
    return re.sub(r"\s+at \S+\.rs:\d+\.?$", "", text)
