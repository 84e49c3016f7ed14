"""A fleet on one Zenoh network (docs/fleet.md): two daemons on simulated robots behind a
router (``cdprctl zenoh-router``), all on 127.0.0.1 without multicast scouting, listed by
``cdprctl robots`` with their states; the line a daemon says about whom it reached; a path's
progress as ``monitor`` draws it; the Zenoh tools' start without numpy."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from types import SimpleNamespace

from conftest import ROOT, end_processes
from test_zenoh import Robot, free_port

from cdprctl.cli import main
from cdprctl.commands.fleet import _reached_at, robot_line
from cdprctl.model.zenoh import ZenohConfig
from cdprctl.telemetry.zenoh.reach import connection_line


def start_router(port: int) -> subprocess.Popen:
    router = subprocess.Popen(
        [sys.executable, "-m", "cdprctl.cli", "zenoh-router", "--listen",
         f"tcp/127.0.0.1:{port}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
    )  # fmt: skip
    assert router.stdout is not None
    first = router.stdout.readline()
    assert first.startswith("zenoh-router: zid ") and f"127.0.0.1:{port}" in first, first
    return router


def test_two_robots_behind_a_router_are_listed_with_their_states(capsys):
    port = free_port()
    where = f"tcp/127.0.0.1:{port}"
    router = start_router(port)
    robots: list[Robot] = []
    try:
        for config in ("rowc.toml", "caroca.toml"):
            robots.append(Robot(["--zenoh-connect", where, "--accept-commands",
                                 "--allow-unauthenticated-commands"], config=config))  # fmt: skip
        for r in robots:  # the daemon said whom its gateway reached
            said = [x for x in r.lines if x.startswith("zenoh: connected to ")]
            assert said and said[0].startswith(f"zenoh: connected to {where}: 1 router, "), r.lines
            assert f"listening on {r.endpoint}" in said[0], said
        tool = ["--connect", where, "--no-multicast-scouting"]

        def listed_until(want: dict[str, str]) -> list[str]:
            """``robots``' lines once they show ``want`` (name → state), or after 20 s."""
            deadline = time.monotonic() + 20.0
            while True:  # how fast it answers: benchmarks, not a test
                capsys.readouterr()
                assert main(["robots", *tool]) == 0
                lines = capsys.readouterr().out.splitlines()
                states = {x.split()[0]: x.split()[1] for x in lines}
                if states == want or time.monotonic() > deadline:
                    assert states == want, lines
                    return lines
                time.sleep(0.2)

        # "ready:" is printed as the start-up ends, a cycle before the state machine is ready
        listed_until({"caroca": "ready", "rowc": "ready"})
        assert main(["send", "--robot", "rowc", *tool, "enable"]) == 0
        listed_until({"caroca": "ready", "rowc": "enabled"})
        assert main(["robots", "--json", *tool]) == 0
        listed = json.loads(capsys.readouterr().out)
        assert [r["prefix"] for r in listed] == ["cdpr/caroca", "cdpr/rowc"]
        assert [r["connect"] for r in listed] == [[where], [where]]
        assert [r["listen"] for r in listed] == [[robots[1].endpoint], [robots[0].endpoint]]
        # a zid is up to 16 bytes in hex, leading zeros not written (31 digits seen)
        assert all(re.fullmatch(r"[0-9a-f]{1,32}", r["zid"]) for r in listed), listed
        assert all(r["reached_at"] in ("", r["listen"][0]) for r in listed), listed
    finally:
        for r in robots:
            r.stop()
        end_processes([router])
    assert all(r.proc.poll() is not None for r in robots) and router.poll() is not None
    out = router.stdout.read() if router.stdout else ""
    assert out.count("zenoh-router: + peer ") >= 2, out  # it said who joined


def test_robots_says_why_it_lists_none(capsys):
    port = free_port()
    tool = ["--connect", f"tcp/127.0.0.1:{port}", "--no-multicast-scouting"]
    assert main(["robots", *tool]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"cdprctl robots: cannot connect to tcp/127.0.0.1:{port}: nothing listens "
                   "there (is the daemon running, with --zenoh-listen on it?)")  # fmt: skip
    assert main(["robots", "--timeout", "5", *tool]) == 2
    assert "--timeout 5: give a time in (0, 1] s" in capsys.readouterr().err
    router = start_router(port)
    try:
        assert main(["robots", *tool]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("cdprctl robots: no robot answers under cdpr/**: connected, but "
                              "no cdprctl gateway answers"), err  # fmt: skip
        assert "\n" not in err
    finally:
        end_processes([router])


class Info:
    def __init__(self, routers: int, peers: int, links: list[str]):
        self.r, self.p = routers, peers
        self.l = [SimpleNamespace(dst=x) for x in links]

    def routers_zid(self) -> list[int]:
        return list(range(self.r))

    def peers_zid(self) -> list[int]:
        return list(range(self.p))

    def links(self) -> list[SimpleNamespace]:
        return self.l


def test_the_line_on_whom_the_gateway_reached():
    zc = ZenohConfig(connect=("tcp/10.0.0.1:7447",), listen=("tcp/0.0.0.0:7448",))
    reached = SimpleNamespace(info=Info(1, 2, ["tcp/10.0.0.7:40000", "tcp/10.0.0.1:7447"]))
    assert connection_line(reached, zc) == ("zenoh: connected to tcp/10.0.0.1:7447: 1 router, "
                                            "2 peers (listening on tcp/0.0.0.0:7448)")  # fmt: skip
    alone = SimpleNamespace(info=Info(0, 0, []))
    line = connection_line(alone, zc)
    assert line.startswith("zenoh: no router/peer reached at tcp/10.0.0.1:7447 (listening on "
                           "tcp/0.0.0.0:7448; the session keeps trying")  # fmt: skip
    line = connection_line(alone, ZenohConfig(listen=("tcp/0.0.0.0:7448",),
                                              multicast_scouting=False))  # fmt: skip
    assert line == ("zenoh: no router/peer reached (no connect endpoint, no multicast scouting; "
                    "listening on tcp/0.0.0.0:7448): tools reach this robot with --connect at "
                    "its listen endpoint")  # fmt: skip


def test_monitor_shows_a_paths_progress(rowc):
    """From the loop's data through the shared snapshot and the state payload to the view:
    segment k of n, the share of the planned time played, the time left."""
    from cdprctl.commands.zenoh_tools import render
    from cdprctl.control.data import ControlData
    from cdprctl.telemetry.snapshot import SharedSnapshot, controller_values
    from cdprctl.telemetry.zenoh.schema import state_payload

    d = ControlData(rowc.n_cables, 0)
    d.tda_method = "barycenter"
    d.motion, d.path_state, d.path_segment, d.path_segments = "path", "running", 3, 6
    d.path_fraction, d.path_elapsed, d.path_time_left = 0.5, 4.0, 6.0
    snap = SharedSnapshot(rowc.n_cables)
    try:
        snap.write(controller_values(d))
        s = snap.read()
        assert s is not None
        state = state_payload(s, [c.name for c in rowc.cables], "")
    finally:
        snap.close()
    assert state["path"] == {"segment": 3, "segments": 6, "fraction": 0.5, "state": "running",
                             "elapsed": 4.0, "time_left": 6.0}  # fmt: skip
    view = render(state, None, {"robot": "rowc"}).splitlines()
    line = next(x for x in view if x.startswith("path "))
    bar = "[" + "#" * 12 + "." * 18 + "]"
    assert line == f"path     segment 3 of 6 (running), 40%, 6.0 s left, {bar}"
    state["path"].update(state="done", segment=6, elapsed=10.0, time_left=0.0)
    assert "path     segment 6 of 6 (done), 100%" in render(state, None, {}).splitlines()
    del state["path"]["elapsed"], state["path"]["time_left"]  # an older daemon: by segments
    state["path"].update(state="paused", segment=2, fraction=0.5)
    assert "path     segment 2 of 6 (paused), 25%" in render(state, None, {}).splitlines()
    state["path"] = None
    assert not any(x.startswith("path ") for x in render(state, None, {}).splitlines())


def test_the_zenoh_tools_start_without_numpy():
    """send, monitor, robots build only their own parsers: none imports numpy or the robot
    model (those imports were a second of every send)."""
    port = free_port()
    code = ("import sys; from cdprctl.cli import main; "
            f"rc = [main([t, *a, '--connect', 'tcp/127.0.0.1:{port}', '--no-multicast-scouting'])"
            " for t, a in (('send', ['--robot', 'r', 'stop']), ('robots', []),"
            " ('monitor', ['--robot', 'r', '--once']))]; "
            "print(rc, sorted(m for m in sys.modules if m.split('.')[0] in "
            "('numpy', 'scipy', 'numba') or m.startswith('cdprctl.model')))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, timeout=60).stdout  # fmt: skip
    assert out.strip() == "[2, 2, 2] []", out


def test_a_robot_line():
    r = {"robot": "rowc", "state": "fault", "fault": "drive 1 silent", "prefix": "cdpr/rowc",
         "zid": "7a9534f64ca2491692888821b6516c38", "reached_at": "", "listen": [],
         "connect": ["tcp/10.0.0.1:7447"], "simulated": False}  # fmt: skip
    assert robot_line(r) == ("rowc         fault     cdpr/rowc            zid 7a9534f6 via "
                             "tcp/10.0.0.1:7447 (drive 1 silent)")  # fmt: skip
    # at: this session's own link to where the robot listens, not the robot's link to it
    assert _reached_at("tcp/192.168.1.2:7450", ["tcp/0.0.0.0:7450"]) == "tcp/192.168.1.2:7450"
    assert _reached_at("tcp/[fd00::2]:57296", ["tcp/127.0.0.1:7450"]) == ""
    assert _reached_at("", ["tcp/127.0.0.1:7450"]) == ""
