"""``make hil``: the hardware-in-the-loop tests (``pytest -m hil``, tests/tools/test_hil.py) on a
real kernel SocketCAN: natively where this machine has vcan0 or can make one, otherwise inside
User-Mode Linux — Debian's ``user-mode-linux`` kernel (vcan built as modules) run as an ordinary
process with this machine's filesystem as its root, so the project, its venv and Python are
there as they are. The tests' output and exit status come back through the shared filesystem;
a kernel that hangs is killed after ``--timeout`` s; nothing is left running.

Where neither is possible — or the User-Mode Linux kernel cannot start a process on this
machine's CPU — the reason is printed and the exit status is 0 with ``--if-possible`` (``make
test`` on a machine that cannot), 1 without it (``make hil``: asked for, not done).
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("user-mode-linux", "kmod", "can-utils")  # Debian's: the kernel, insmod, candump
UML = "linux.uml"
# can-dev before vcan (its dependency); can and can-raw for the sockets
MODULES = ("net/can/can.ko", "net/can/can-raw.ko", "drivers/net/can/dev/can-dev.ko",
           "drivers/net/can/vcan.ko")  # fmt: skip
INIT = """#!/bin/sh
# User-Mode Linux's init (tools/hil.py): mounts, the CAN modules, vcan0, the tests, halt
echo started > {started}
mount -t proc proc /proc; mount -t sysfs sys /sys
mount -t devtmpfs dev /dev 2>/dev/null; mkdir -p /dev/shm; mount -t tmpfs shm /dev/shm
mount -t tmpfs run /run
M=/usr/lib/uml/modules/$(uname -r)/kernel
for m in {modules}; do insmod "$M/$m" || echo "hil: insmod $m failed"; done
ip link add dev vcan0 type vcan && ip link set up vcan0
ip link set lo up
cd {root}
export PATH={path}:/usr/sbin:/sbin HOME={home} PYTHONDONTWRITEBYTECODE=1 CDPRCTL_HIL=uml {extra}
{python} -m pytest -m hil -p no:cacheprovider --basetemp={basetemp} {args} > {out} 2>&1
echo $? > {rc}
halt -f
"""


def can_sockets() -> bool:
    """Whether this kernel has SocketCAN (socket(AF_CAN) fails with errno 97 where not)."""
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        return True
    except (OSError, AttributeError):
        return False


def native_vcan0() -> str | None:
    """vcan0 on this machine, up, made if it can be (root, the vcan module); None, or why
    not."""
    root = os.geteuid() == 0
    if not can_sockets() and root and shutil.which("modprobe"):
        subprocess.run(["modprobe", "can-raw"], capture_output=True)  # where only unloaded
    if not can_sockets():
        return "this kernel has no CAN support (socket(AF_CAN): errno 97)"
    up = Path("/sys/class/net/vcan0/operstate")

    def is_up() -> bool:
        return up.exists() and up.read_text().strip() in ("up", "unknown")  # vcan: unknown

    if is_up():
        return None
    if not root:
        return ("vcan0 is down, and not root to bring it up" if up.exists()
                else "no vcan0, and not root to make one")  # fmt: skip
    for cmd in (["modprobe", "vcan"], ["ip", "link", "add", "dev", "vcan0", "type", "vcan"],
                ["ip", "link", "set", "up", "vcan0"]):  # fmt: skip
        if shutil.which(cmd[0]) is None:
            return f"no vcan0, and no `{cmd[0]}` to make one"
        subprocess.run(cmd, capture_output=True)
    if is_up():
        return None
    return "no vcan0, and `ip link add dev vcan0 type vcan` did not make one"


def uml_ready(install: bool) -> str | None:
    """User-Mode Linux with vcan, installed from Debian's packages where root and apt allow
    (``install``); None, or why it is not there."""
    if shutil.which(UML) and shutil.which("candump") and shutil.which("insmod"):
        return None
    missing = [p for p, tool in zip(PACKAGES, (UML, "insmod", "candump"), strict=True)
               if shutil.which(tool) is None]  # fmt: skip
    if not install:
        return f"User-Mode Linux not installed: apt-get install {' '.join(missing)}"
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        return (f"User-Mode Linux not installed and not root with apt-get to install it: "
                f"apt-get install {' '.join(missing)}")  # fmt: skip
    print(f"hil: installing {' '.join(missing)} (Debian's User-Mode Linux, for vcan0)",
          flush=True)  # fmt: skip
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    done = subprocess.run(["apt-get", "install", "-y", "-q", *missing], env=env,
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:  # an old package list: once more after an update
        subprocess.run(["apt-get", "update", "-q"], env=env, capture_output=True)
        done = subprocess.run(["apt-get", "install", "-y", "-q", *missing], env=env,
                              capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0 or shutil.which(UML) is None:
        return f"apt-get install {' '.join(missing)} failed: {done.stderr.strip()[-300:]}"
    return None


def run_native(args: list[str]) -> int:
    env = {**os.environ, "CDPRCTL_HIL": "native"}
    return subprocess.run([sys.executable, "-m", "pytest", "-m", "hil", "-p", "no:cacheprovider",
                           *args], cwd=ROOT, env=env).returncode  # fmt: skip


def run_uml(args: list[str], timeout: float, memory: str) -> int:
    """The tests inside User-Mode Linux; their output printed here; their exit status, or 1
    when the kernel hung (killed after ``timeout`` s) or ended without one."""
    work = Path(tempfile.mkdtemp(prefix="cdprctl-hil-"))
    try:
        out, rc = work / "pytest.txt", work / "rc"
        passed_on = ("CDPRCTL_VENDOR_EDS", "NUMBA_CACHE_DIR", "PYTHONPATH")
        extra = " ".join(f"{k}={shlex.quote(os.environ[k])}" for k in passed_on
                         if k in os.environ)  # fmt: skip
        init = work / "init.sh"
        q = shlex.quote
        init.write_text(INIT.format(
            modules=" ".join(MODULES), root=q(str(ROOT)),
            path=q(os.environ.get("PATH", "/usr/bin:/bin")),
            home=q(os.environ.get("HOME", "/root")), extra=extra, python=q(sys.executable),
            args=" ".join(q(x) for x in args), out=q(str(out)), rc=q(str(rc)),
            basetemp=q(str(work / "pytest")),  # its own: the kernel runs pytest as root
            started=q(str(work / "started")),
        ))  # fmt: skip
        init.chmod(0o755)
        console = work / "console.txt"
        start = time.monotonic()
        hung = False
        with console.open("w") as con:
            uml = subprocess.Popen(
                [UML, f"mem={memory}", "rootfstype=hostfs", "rootflags=/", "rw",
                 f"init={init}", "con=null", "con0=fd:0,fd:1"],
                stdin=subprocess.DEVNULL, stdout=con, stderr=subprocess.STDOUT,
                start_new_session=True,
            )  # fmt: skip
            stopped = signal.signal(signal.SIGTERM, _interrupt)  # a cancelled CI job
            try:
                uml.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                hung = True
                print(f"hil: the User-Mode Linux kernel did not end in {timeout:g} s: killed",
                      file=sys.stderr)  # fmt: skip
            except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the kernel goes with us
                print("hil: interrupted: the User-Mode Linux kernel killed", file=sys.stderr)
                return 130
            finally:
                signal.signal(signal.SIGTERM, stopped)
                if uml.poll() is None:
                    os.killpg(uml.pid, signal.SIGKILL)
                    uml.wait()
        took = time.monotonic() - start
        if out.exists():
            sys.stdout.write(out.read_text())
        if not rc.exists() and not hung and not (work / "started").exists():
            raise UmlCannotStartError(console.read_text() if console.exists() else "")
        if not rc.exists():
            tail = console.read_text()[-2000:] if console.exists() else ""
            print(f"hil: no exit status from inside User-Mode Linux; its console:\n{tail}",
                  file=sys.stderr)  # fmt: skip
            return 1
        print(f"hil: inside User-Mode Linux (vcan0, one slow CPU), {took:.0f} s with its boot")
        return int(rc.read_text().strip() or 1)
    finally:
        shutil.rmtree(work, ignore_errors=True)


class UmlCannotStartError(Exception):
    """The User-Mode Linux kernel ended before its init ran a line: this machine cannot run
    it (Debian's 6.1 UML kernel on a CPU with AMX state: "userspace - ptrace set fp regs
    failed, errno = 14", then a panic, before any process of ours). Not the tests' failure:
    they never started."""

    def __init__(self, console: str):
        lines = [x.strip() for x in console.splitlines()]
        said = next((x for x in lines if "failed, errno" in x), None) or next(
            (x for x in lines if "panic" in x.lower()), None) or next(
            (x for x in reversed(lines) if x), "no console output")  # fmt: skip
        super().__init__(f"User-Mode Linux could not start a process on this machine "
                         f"(its kernel said: {said!r}); the tests did not run")  # fmt: skip


def _interrupt(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--if-possible", action="store_true",
                    help="exit 0, saying why, where neither vcan0 nor User-Mode Linux can be had")
    ap.add_argument("--where", choices=("auto", "native", "uml"), default="auto",
                    help="native: this machine's vcan0; uml: User-Mode Linux even where vcan0 is")
    ap.add_argument("--timeout", type=float, default=900.0, help="s before a hung kernel is killed")
    ap.add_argument("--memory", default="2G", help="User-Mode Linux's memory (mem=)")
    ap.add_argument("pytest_args", nargs="*", help="passed to pytest (after --)")
    a = ap.parse_args(argv)
    where, why = plan(a.where, native_vcan0, lambda: uml_ready(install=True))
    if where == "native":
        print("hil: on this machine's vcan0", flush=True)
        return run_native(a.pytest_args)
    if where == "uml":
        print(f"hil: {why}: inside User-Mode Linux", flush=True)
        try:
            return run_uml(a.pytest_args, a.timeout, a.memory)
        except UmlCannotStartError as exc:
            print(f"hil: not run: {exc}", file=sys.stderr)
            return 0 if a.if_possible else 1
    print(f"hil: not run: {why}", file=sys.stderr)
    return 0 if a.if_possible else 1


def plan(where: str, native: Callable[[], str | None], uml: Callable[[], str | None]
         ) -> tuple[str | None, str]:  # fmt: skip
    """Where the tests run — "native", "uml" or None — and why not the other way. ``native``
    and ``uml`` say why each cannot be had (None: it can); asked only as needed, in that order
    (User-Mode Linux may be installed on the way)."""
    why_not_native = native() if where != "uml" else "asked for User-Mode Linux"
    if why_not_native is None:
        return "native", ""
    why_not_uml = uml() if where != "native" else "asked for this machine's vcan0"
    if why_not_uml is None:
        return "uml", why_not_native
    return None, f"{why_not_native}; {why_not_uml}"

if __name__ == "__main__":
    sys.exit(main())
