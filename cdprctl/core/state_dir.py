"""Where a robot's records live: a real robot's state directory (``/var/lib/cdprctl/<robot>``,
the systemd unit's ``StateDirectory=cdprctl``) and a simulated robot's, apart from it — a
simulation never writes where a real robot's records live — and whether a directory can be
written, checked before anything moves (docs/operating.md, "Records")."""

from __future__ import annotations

import json
import os
import pwd
import stat
import tempfile
from pathlib import Path

REAL_ROOT = Path("/var/lib/cdprctl")
# what the procedures keep: their records and the samples of a stop midway (partial_session)
RECORD_FILES = ("calibration.json", "brake_test.json", "calibration-geometry.partial.json",
                "calibration-self.partial.json", "brake_test.partial.json", "load_cells.json")


class StateDirError(Exception):
    """A state directory a command may not or cannot write: one line with the fix."""


def default_state_dir(robot: str) -> Path:
    """``/var/lib/cdprctl/<robot>``: the systemd unit's ``StateDirectory=cdprctl``."""
    return REAL_ROOT / robot


def simulated_state_dir(robot: str) -> Path:
    """Where a simulated robot's records go when no ``--state-dir`` is given:
    ``$XDG_STATE_HOME/cdprctl/simulated/<robot>`` (``~/.local/state`` by default), the
    user's own and never under ``/var/lib/cdprctl``."""
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "cdprctl" / "simulated" / robot


def real_records_in(path: Path) -> list[str]:
    """The record files in ``path`` that are not marked ``"simulated": true``: a real
    robot's (an unreadable one counts as real: nothing proves it is not)."""
    out = []
    for name in RECORD_FILES:
        f = Path(path) / name
        if not f.exists():
            continue
        try:
            simulated = json.loads(f.read_text()).get("simulated") is True
        except (OSError, ValueError, AttributeError):
            simulated = False
        if not simulated:
            out.append(name)
    return out


def _under_real_root(path: Path) -> bool:
    real = REAL_ROOT.resolve()
    p = Path(path).resolve()
    return p == real or real in p.parents


def state_dir_for(robot: str, given: str | None, simulated: bool) -> Path:
    """The directory a command's record goes to: ``given`` (``--state-dir``) or the default,
    a real robot's or a simulated one's. A simulation given a real robot's directory is
    refused (:class:`StateDirError`): under ``/var/lib/cdprctl``, or holding a record that
    is not a simulated one."""
    if not simulated:
        return Path(given) if given else default_state_dir(robot)
    if not given:
        return simulated_state_dir(robot)
    # resolved: "/var/lib/cdprctl/../../tmp/y" is /var/tmp/y, and the directory made and
    # written is the one checked (made as given, its ".." made /var/lib/cdprctl on the way)
    path = Path(given).resolve()
    fix = (f"leave --state-dir out (a simulation writes to {simulated_state_dir(robot)}) or "
           "give a directory of its own")  # fmt: skip
    if _under_real_root(path):
        raise StateDirError(f"--state-dir {path}: under {REAL_ROOT}, where real robots' "
                            f"records live, and this robot is simulated: {fix}")  # fmt: skip
    real = real_records_in(path)
    if real:
        raise StateDirError(f"--state-dir {path} holds a real robot's {', '.join(real)}, and "
                            f"this robot is simulated (a simulation never writes over a real "
                            f"robot's records): {fix}")  # fmt: skip
    return path


def _user_name(uid: int) -> str:
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:  # a uid without a passwd entry (a container's)
        return f"uid {uid}"


def _owner_of_nearest(path: Path) -> str:
    """"owner NAME, mode 0755" of ``path`` or its nearest existing parent."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        st = p.stat()
    except OSError:
        return str(p)
    return f"{p}: owner {_user_name(st.st_uid)}, mode {stat.S_IMODE(st.st_mode):04o}"


def check_writable(path: Path, option: str = "--state-dir") -> None:
    """Create ``path`` if needed and write a file in it (removed at once);
    :class:`StateDirError` naming the directory, why, its owner and the fix otherwise."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as exc:
        why = exc.strerror or str(exc)
        raise StateDirError(
            f"cannot write the state directory {path} ({why}; {_owner_of_nearest(path)}; "
            f"you are {_user_name(os.getuid())}): run as its owner (the service's "
            f"user) or give {option} DIR, a directory you can write"
        ) from None
