"""Who Zenoh refused, from Zenoh's own log lines (recorded from Zenoh 1.10.2 on this machine:
a viewer's five commands, an operator's three, a wrong password, a certificate of another CA
and none): one line per kind of refusal at once, then how many more, never a line for a
command another of the peer's ACL subjects allowed, nor for the permissions Zenoh caches."""

from __future__ import annotations

from pathlib import Path

from cdprctl.telemetry.refusals import Refusals

T = "TRACE  rx-0 ThreadId(09) zenoh::net::routing::interceptor::access_control: "
VIEWER = ("3daf7a8123c1b54e817939a7ddb0e1d on Interface(lo)+Username(viewer)+Transport(Tcp)+"
          "3daf7a8123c1b54e817939a7ddb0e1d")  # fmt: skip
OPERATOR = ("4835a894cbd93b23f8fcea2d8841bc7f on Interface(lo)+Username(operator)+"
            "Transport(Tcp)+4835a894cbd93b23f8fcea2d8841bc7f")  # fmt: skip
TLS_VIEWER = ("d0f7f0aab37c48f6429e7441a7efa5ea on Interface(lo)+CertCommonName(viewer)+"
              "Transport(Tls)+d0f7f0aab37c48f6429e7441a7efa5ea")  # fmt: skip
ACC = "DEBUG acc-0 ThreadId(05) "
CACHING = (ACC.replace("DEBUG", "TRACE") + "zenoh::net::routing::interceptor::access_control: "
           "ACL (ingress): caching permissions for `cdpr/rowc/cmd` ...")  # fmt: skip


def at(clock: str, rest: str) -> str:
    return f"2026-12-03T19:59:{clock}Z {rest}"


def put(who: str, verdict: str, key: str = "cdpr/rowc/cmd/enable") -> str:
    return f"{T}{who} is {verdict} to Put (ingress) on {key}"


def feed(lines: list[tuple[float, str]], prefix: str = "cdpr/rowc", **kw) -> list[str]:
    out: list[str] = []
    r = Refusals(prefix, out.append, **kw)
    for now, line in lines:
        r.feed(line, now)
    r.tick(lines[-1][0] + 60.0)
    return out


def test_a_denied_command_is_named_once_with_who_then_counted():
    lines = [(0.0, at("53.192803", CACHING)),
             (0.0, at("53.192830", T.replace("rx-0 ThreadId(09)", "acc-0 ThreadId(05)")
                      + VIEWER + " is unauthorized to Put (ingress) on cdpr/rowc/cmd"))]
    for i in range(5):  # five puts 0.1 s apart, as recorded
        clock = f"{53.697118 + 0.1 * i:09.6f}"
        lines.append((0.5 + 0.1 * i, at(clock, put(VIEWER, "unauthorized"))))
    out = feed(lines)
    assert out == [
        "cdprctl-zenoh: refused by the access control: user viewer (peer 3daf7a81 on lo) may "
        "not put cdpr/rowc/cmd/enable",
        "cdprctl-zenoh: refused by the access control: user viewer may not put "
        "cdpr/rowc/cmd/enable (again, 4 more times in the last 10 s)",
    ]


def test_a_users_sessions_count_together():
    """Every `cdprctl send` is a new Zenoh peer: twenty of a viewer's, a line and a count."""
    lines = []
    for i in range(20):
        zid = f"{i + 1:02d}af7a8123c1b54e817939a7ddb0e1d"
        who = f"{zid} on Interface(lo)+Username(viewer)+Transport(Tcp)+{zid}"
        lines.append((0.2 * i, at(f"{10 + 0.2 * i:09.6f}", put(who, "unauthorized"))))
    out = feed(lines)
    assert out == [
        "cdprctl-zenoh: refused by the access control: user viewer (peer 01af7a81 on lo) may "
        "not put cdpr/rowc/cmd/enable",
        "cdprctl-zenoh: refused by the access control: user viewer may not put "
        "cdpr/rowc/cmd/enable (again, 19 more times in the last 10 s)",
    ]


def test_an_operators_command_allowed_by_its_second_subject_is_no_refusal():
    """Zenoh judges each subject a peer matches: "authenticated" refuses, "operator" allows;
    the message went through."""
    lines = []
    for i in range(3):
        t = 0.1 * i
        lines.append((t, at(f"{56.745793 + t:09.6f}", put(OPERATOR, "unauthorized"))))
        lines.append((t, at(f"{56.745832 + t:09.6f}", put(OPERATOR, "authorized"))))
    assert feed(lines) == []


def test_one_message_judged_for_two_refusing_subjects_counts_once():
    lines = [(0.0, at("10.000100", put(VIEWER, "unauthorized"))),
             (0.0, at("10.000130", put(VIEWER, "unauthorized")))]  # fmt: skip
    out = feed(lines)
    assert len(out) == 1 and "again" not in out[0]


def test_another_robots_keys_and_the_cached_permissions_are_not_refusals():
    assert feed([(0.0, at("10.0", put(VIEWER, "unauthorized", "cdpr/caroca/cmd/enable")))]) == []
    assert feed([(0.0, at("53.192803", CACHING)),
                 (0.0, at("53.192830", ACC.replace("DEBUG", "TRACE")
                          + "zenoh::net::routing::interceptor::access_control: " + VIEWER
                          + " is unauthorized to Put (ingress) on cdpr/rowc/cmd"))]) == []


def test_a_certificates_common_name_says_who():
    out = feed([(0.0, at("10.0", put(TLS_VIEWER, "unauthorized")))])
    assert out == ["cdprctl-zenoh: refused by the access control: certificate viewer "
                   "(peer d0f7f0aa on lo) may not put cdpr/rowc/cmd/enable"]  # fmt: skip


def test_refused_logins_name_the_address_and_why():
    usrpwd = (ACC + "zenoh_transport::unicast::establishment::accept: UsrPwd extension - Recv "
              "OpenSyn. Invalid {}. at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/"
              "cc83980/io/zenoh-transport/src/unicast/establishment/ext/auth/usrpwd.rs:424.")
    tcp = ACC + "zenoh_link_tcp::unicast: Accepted TCP connection on 127.0.0.1:7999: {}"
    lines = [(0.0, at("55.44", tcp.format("127.0.0.1:39498"))),
             (0.0, at("55.45", usrpwd.format("password"))),
             (1.0, at("56.44", tcp.format("127.0.0.1:39510"))),
             (1.0, at("56.45", usrpwd.format("password"))),
             (2.0, at("57.44", tcp.format("10.0.0.7:33928"))),
             (2.0, at("57.45", usrpwd.format("user"))),
             (3.0, at("58.44", tcp.format("127.0.0.1:44588"))),
             (3.0, at("58.45", usrpwd.format("user").replace(
                 "OpenSyn. Invalid user", "InitSyn. Expected extension")))]  # fmt: skip
    assert feed(lines) == [
        "cdprctl-zenoh: refused a login from 127.0.0.1: wrong password",
        "cdprctl-zenoh: refused a login from 10.0.0.7: unknown user",
        "cdprctl-zenoh: refused a login from 127.0.0.1: no user and password given",
        "cdprctl-zenoh: refused a login from 127.0.0.1: wrong password (again, 1 more time in "
        "the last 10 s)",
    ]


def test_refused_certificates_say_what_was_wrong_without_zenohs_hint():
    warn = (" WARN acc-0 ThreadId(05) zenoh_link_tls::unicast: {}. Hint: increase the system "
            "open file limit.")
    lines = [(0.0, at("33.938685", warn.format("invalid peer certificate: BadSignature"))),
             (1.0, at("35.496711", warn.format("peer sent no certificates"))),
             (2.0, at("36.0", warn.format("received fatal alert: UnknownCA"))),
             (3.0, at("37.0", warn.format("tls handshake eof")))]  # fmt: skip
    assert feed(lines) == [
        "cdprctl-zenoh: refused a TLS connection: invalid peer certificate: BadSignature (a "
        "certificate this robot's CA did not sign)",
        "cdprctl-zenoh: refused a TLS connection: peer sent no certificates (a client without "
        "a certificate)",
        "cdprctl-zenoh: refused a TLS connection: received fatal alert: UnknownCA (the client "
        "does not trust this robot's certificate: its root_ca_certificate is not this robot's "
        "CA)",
    ]  # a connection closed before its handshake (a port probe, `send`'s reachability
    # check) is no refusal


def test_a_flood_is_a_line_per_kind_every_ten_seconds():
    lines = [(i * 0.001, at(f"{10 + i * 0.002:09.6f}", put(VIEWER, "unauthorized")))
             for i in range(20000)]  # 20 s of a put every 2 ms (read every 1 ms)
    out = feed(lines)
    assert 2 <= len(out) <= 4, out
    counted = sum(int(x.split("again, ")[1].split(" ")[0]) for x in out if "again" in x)
    assert counted + 1 == 20000


def test_with_rust_log_every_line_goes_on_as_it_came():
    line = at("10.0", put(VIEWER, "unauthorized"))
    out = feed([(0.0, line), (0.0, "not a log line")], passthrough=True)
    assert out[:2] == [line, "not a log line"] and "refused" in out[2]


def test_a_message_judged_across_a_minute_or_an_hour_is_one_and_the_clock_is_whole():
    """Zenoh's timestamps, whole: the same message judged at 19:59:59.9998 and 20:00:00.0001
    for two subjects is one refusal; two messages with the same seconds a minute or an hour
    apart are two."""
    def at_clock(clock: str, rest: str) -> str:
        return f"2026-12-03T{clock}Z {rest}"

    one = [(0.0, at_clock("19:59:59.999800", put(VIEWER, "unauthorized"))),
           (0.0, at_clock("20:00:00.000100", put(VIEWER, "unauthorized")))]  # fmt: skip
    assert len(feed(one)) == 1
    for later in ("20:00:10.000100", "21:59:10.000100"):
        two = [(0.0, at_clock("20:59:10.000100", put(VIEWER, "unauthorized"))),
               (0.0, at_clock(later, put(VIEWER, "unauthorized")))]  # fmt: skip
        out = feed(two)
        assert len(out) == 2 and "again, 1 more time" in out[1], out


def test_the_pipe_carries_zenohs_log_lines_to_the_daemons_refusal_lines(tmp_path):
    """``log_refusals`` in a process of its own: what is written on its fd 1 (where Zenoh
    writes its log) comes out as refusal lines on stderr, and Python's own prints still reach
    the real stdout."""
    import subprocess
    import sys

    line = at("10.000000", put(VIEWER, "unauthorized")) + "\n"
    script = tmp_path / "pipe.py"
    script.write_text(
        "import os, time\n"
        "from cdprctl.telemetry.refusals import log_refusals\n"
        "log_refusals('cdpr/rowc')\n"
        "print('python output', flush=True)\n"
        f"os.write(1, {line.encode()!r})\n"
        "time.sleep(0.6)\n"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "RUST_LOG"}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1])  # this tree's cdprctl
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=60, env=env)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "python output" in res.stdout and "ThreadId" not in res.stdout
    assert ("cdprctl-zenoh: refused by the access control: user viewer (peer 3daf7a81 on lo) "
            "may not put cdpr/rowc/cmd/enable") in res.stderr, res.stderr
