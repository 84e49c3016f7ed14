"""Who Zenoh refused, from Zenoh's own log lines (recorded from Zenoh 1.10.2 on this machine:
a viewer's five commands, an operator's three, a wrong password, a certificate of another CA
and none): one line per kind of refusal at once, then how many more, never a line for a
command another of the peer's ACL subjects allowed, nor for the permissions Zenoh caches."""

from __future__ import annotations

from pathlib import Path

from cdprctl.telemetry.zenoh.refusals import Refusals

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
    """``log_refusals`` in a process of its own: Zenoh's log asked for with cdprctl's filter
    (the user's with RUST_LOG); what is written on its fd 1 (where Zenoh writes its log, a pipe
    of 1 MiB) comes out as refusal lines on stderr — also a line after a silence, and settled
    by the silence itself; Python's own prints still reach the real stdout, a line at a time."""
    import os
    import select
    import subprocess
    import sys

    line = at("10.000000", put(VIEWER, "unauthorized")) + "\n"
    script = tmp_path / "pipe.py"
    script.write_text(
        "import fcntl, os, sys, time, zenoh\n"
        "real = fcntl.fcntl\n"
        "def refusing(fd, cmd, *a):\n"  # as where pipe-max-size is below 1 MiB
        "    if cmd == 1031: raise PermissionError(1, 'Operation not permitted')\n"
        "    return real(fd, cmd, *a)\n"
        "if os.environ.get('PIPE_SZ_REFUSED'): fcntl.fcntl = refusing\n"
        "asked = []\n"
        "zenoh.init_log_from_env_or = lambda f: asked.append(('ours', f))\n"
        "zenoh.try_init_log_from_env = lambda: asked.append(('env', None))\n"
        "from cdprctl.telemetry.zenoh.refusals import log_refusals\n"
        "log_refusals('cdpr/rowc')\n"
        "print(asked, fcntl.fcntl(1, 1032))\n"  # F_GETPIPE_SZ of Zenoh's fd 1
        "sys.stdin.readline()\n"  # the test saw the line before this process ends
        "time.sleep(0.5)\n"  # a silence: the reader's wait times out twice
        f"os.write(1, {line.encode()!r})\n"
        "time.sleep(0.5)\n"  # settled by the next time-out, no line after it
    )
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[3])  # this tree's cdprctl
    for rust_log, size in ((None, 1 << 20), ("zenoh=info", 1 << 20), (None, 0)):
        env.pop("RUST_LOG", None)
        if rust_log:
            env["RUST_LOG"] = rust_log
        env["PIPE_SZ_REFUSED"] = "" if size else "1"  # then the pipe keeps its size
        p = subprocess.Popen([sys.executable, str(script)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=env)  # fmt: skip
        try:
            assert p.stdout is not None and p.stdin is not None
            ready, _, _ = select.select([p.stdout], [], [], 60.0)
            said = p.stdout.readline() if ready else ""
            p.stdin.write("go\n")
            p.stdin.close()
            p.wait(timeout=60)
            out, err = p.stdout.read(), p.stderr.read()  # a few lines: no pipe fills
        finally:
            if p.poll() is None:
                p.kill()
                p.wait()
        assert p.returncode == 0, err
        from cdprctl.telemetry.zenoh.refusals import ZENOH_LOG_FILTER

        asked = [("env", None)] if rust_log else [("ours", ZENOH_LOG_FILTER)]
        assert said == f"{asked!r} {size or 65536}\n", (said, err)
        assert "ThreadId" not in out if not rust_log else line.strip() in out
        assert ("cdprctl-zenoh: refused by the access control: user viewer (peer 3daf7a81 on "
                "lo) may not put cdpr/rowc/cmd/enable") in err, err


def test_pending_verdicts_settle_at_settle_and_counts_come_at_every():
    """A refusal is written once its verdict has waited ``SETTLE`` (no "authorized" for it from
    another subject) — at that instant, not a tick later — and a count once ``every`` s have
    passed since the kind's last line, at that instant too."""
    from cdprctl.telemetry.zenoh.refusals import SETTLE

    out: list[str] = []
    r = Refusals("cdpr/rowc", out.append, every=10.0)
    r.feed(at("10.000000", put(VIEWER, "unauthorized")), 0.0)
    r.feed("an unrelated line", SETTLE / 2)
    assert out == []
    r.feed("an unrelated line", SETTLE)
    assert len(out) == 1 and "user viewer (peer 3daf7a81 on lo)" in out[0]
    r.feed(at("11.000000", put(VIEWER, "unauthorized")), 1.0)
    r.feed(at("12.000000", put(VIEWER, "unauthorized")), 2.0)
    r.tick(2.0 + SETTLE)
    r.tick(SETTLE + 10.0 - 1e-9)
    assert len(out) == 1
    r.tick(SETTLE + 10.0)
    assert out[1].endswith("(again, 2 more times in the last 10 s)"), out


def test_a_flood_of_lines_ticks_every_settle_not_every_line():
    """Settling costs a pass over what is pending: on a line every millisecond it runs every
    ``SETTLE`` (20 times a second), from the first line on, not on every line."""
    from cdprctl.telemetry.zenoh.refusals import SETTLE

    r = Refusals("cdpr/rowc", lambda _: None)
    ticks: list[float] = []
    tick = r.tick

    def counted(now: float) -> None:
        ticks.append(now)
        tick(now)

    r.tick = counted  # type: ignore[method-assign]
    for i in range(1000):
        r.feed("a line", 100.0 + i * 0.001)
    assert ticks[0] == 100.0 and len(ticks) == round(1.0 / SETTLE)


def test_the_oldest_kinds_are_forgotten_beyond_kept():
    """256 kinds of refusal are remembered for their counts (a bound on the memory a flood
    of distinct refusals takes); one more forgets the one refused least recently, which is
    then written anew when it comes back."""
    KEPT = 256
    out: list[str] = []
    r = Refusals("cdpr/rowc", out.append)

    def refuse(i: int, now: float) -> None:
        r.feed(at("10.000000", put(VIEWER, "unauthorized", f"cdpr/rowc/cmd/k{i}")), now)
        r.tick(now + 1.0)

    def first_lines() -> list[str]:  # a kind's first line, not its counts
        return [x for x in out if "again" not in x]

    for i in range(KEPT):
        refuse(i, 2.0 * i)
    refuse(0, 2.0 * KEPT)  # refused again: now the most recent
    assert len(first_lines()) == KEPT
    refuse(KEPT, 2.0 * KEPT + 2.0)  # one more kind: k1, the least recent, is forgotten
    refuse(0, 2.0 * KEPT + 4.0)
    assert len(first_lines()) == KEPT + 1
    refuse(1, 2.0 * KEPT + 6.0)
    assert len(first_lines()) == KEPT + 2 and out[-1].endswith("may not put cdpr/rowc/cmd/k1")


def test_only_tls_warnings_are_tls_refusals_and_an_ipv6_address_is_whole():
    """A TLS debug line or a TCP warning is no refused certificate; a refused login from an
    IPv6 peer names its whole address."""
    tls_debug = ACC + "zenoh_link_tls::unicast: TLS handshake with 127.0.0.1:4000 done"
    tcp_warn = " WARN acc-0 ThreadId(05) zenoh_link_tcp::unicast: peer sent no certificates"
    assert feed([(0.0, at("10.0", tls_debug)), (0.1, at("10.1", tcp_warn))]) == []
    tcp = ACC + "zenoh_link_tcp::unicast: Accepted TCP connection on [::1]:7999: [::1]:39498"
    login = (ACC + "zenoh_transport::unicast::establishment::accept: UsrPwd extension - Recv "
             "OpenSyn. Invalid password.")  # fmt: skip
    assert feed([(0.0, at("10.0", tcp)), (0.0, at("10.1", login))]) == [
        "cdprctl-zenoh: refused a login from [::1]: wrong password"]


def test_verdicts_a_millisecond_apart_are_two_messages():
    """The same message judged for two subjects comes within ``SAME_MESSAGE`` (1 ms); two
    verdicts exactly 1 ms apart are two messages."""
    two = [(0.0, f"2026-12-03T00:00:00.000Z {put(VIEWER, 'unauthorized')}"),
           (0.0, f"2026-12-03T00:00:00.001Z {put(VIEWER, 'unauthorized')}")]  # fmt: skip
    out = feed(two)
    assert len(out) == 2 and "again, 1 more time in" in out[1], out


def test_a_peer_without_user_or_certificate_is_named_by_its_id():
    """No user, no certificate: the peer's first 8 hex digits, in the first line and the
    count's."""
    zid = "0123456789abcdef0123456789abcdef"
    out = feed([(0.0, at("10.0", put(zid, "unauthorized"))),
                (1.0, at("11.0", put(zid, "unauthorized")))])  # fmt: skip
    assert out == [
        "cdprctl-zenoh: refused by the access control: peer 01234567 may not put "
        "cdpr/rowc/cmd/enable",
        "cdprctl-zenoh: refused by the access control: peer 01234567 may not put "
        "cdpr/rowc/cmd/enable (again, 1 more time in the last 10 s)",
    ]


def test_refuses_anybody_names_each_way_a_configuration_refuses(tmp_path):
    """A user/password dictionary, mutual TLS or an access control refuse somebody (and the
    daemon then reads Zenoh's log); none of them, or a file Zenoh cannot read, nobody."""
    from cdprctl.telemetry.zenoh.refusals import refuses_anybody

    bodies = {
        '{transport: {auth: {usrpwd: {user: "a", password: "b", dictionary_file: "d.txt"}}}}':
            True,
        '{transport: {link: {tls: {enable_mtls: true}}}}': True,
        '{access_control: {enabled: true, default_permission: "deny"}}': True,
        '{access_control: {enabled: false}}': False,
        '{transport: {auth: {usrpwd: {user: "a", password: "b"}}}}': False,
        "{}": False,
        "{ not json5 at all": False,
    }  # fmt: skip
    for i, (body, refuses) in enumerate(bodies.items()):
        f = tmp_path / f"z{i}.json5"
        f.write_text(body)
        assert refuses_anybody(str(f)) is refuses, body
