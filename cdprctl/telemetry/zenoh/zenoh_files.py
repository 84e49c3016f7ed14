"""The files a Zenoh configuration names — TLS certificates and keys, the user/password
dictionary — checked before a session is opened. Zenoh reports a missing one only when the
session opens: inside the gateway's process that was a traceback, then a 20 s wait for a
gateway that had died. Here it is one line naming the key, the file and how to make it.

Read with Zenoh's own parser, so the file checked is the one the session would open (a relative
path is taken from the working directory, as Zenoh takes it)."""

from __future__ import annotations

from pathlib import Path

from cdprctl.telemetry.zenoh.security import config_value, zenoh_error

MAKE_CERTS = (
    "create the certificates with tools/make_certs.sh DIR (docs/telemetry.md, \"Security\") "
    "and point the key at them"
)
MAKE_DICTIONARY = (
    "create it: one user:password line per account, as in "
    "config/zenoh/zenoh-users.txt.example, readable only by the daemon's user"
)
#: key (as zenoh.Config.get_json takes it) → how to make the file it names
FILE_KEYS = {
    "transport/link/tls/root_ca_certificate": MAKE_CERTS,
    "transport/link/tls/listen_certificate": MAKE_CERTS,
    "transport/link/tls/listen_private_key": MAKE_CERTS,
    "transport/link/tls/connect_certificate": MAKE_CERTS,
    "transport/link/tls/connect_private_key": MAKE_CERTS,
    "transport/auth/usrpwd/dictionary_file": MAKE_DICTIONARY,
}


def missing_files(config_file: str) -> list[str]:
    """What is wrong with the files ``config_file`` names (empty: nothing, or no file given):
    each missing one as ``FILE: key = PATH: no such file; how to make it``."""
    if not config_file:
        return []
    import zenoh

    if not Path(config_file).is_file():
        return [f"{config_file}: no such file"]
    try:
        conf = zenoh.Config.from_file(config_file)
    except Exception as exc:
        return [f"{config_file}: not a Zenoh configuration ({zenoh_error(exc)})"]
    out = []
    for key, fix in FILE_KEYS.items():
        value = config_value(conf, key)
        if isinstance(value, str) and value and not Path(value).is_file():
            out.append(f"{config_file}: {key.replace('/', '.')} = {value}: no such file; {fix}")
    return out

