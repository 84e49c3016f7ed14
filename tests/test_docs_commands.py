"""Every ``cdprctl`` command in a fenced block of the README and docs/ is one the command line
takes as written: parsed by cdprctl's own parser (an unknown option, a missing argument or a
wrong sub-command fails here, not in a user's terminal), a Zenoh tool given the robot it talks
to (``--robot`` or ``--prefix``: a documented step once had neither), and every file it names
by a path in this repository present. Those that need no robot are run as written (exit 0,
their plots written); the daemon and the tools against a live gateway are the other tests'
work."""

from __future__ import annotations

import itertools
import re
import shlex
from pathlib import Path

import pytest

from cdprctl.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
ZENOH_TOOLS = {"send", "monitor", "record", "jog"}
FILE_OPTIONS = {"--config", "--path", "--file", "--zenoh-config"}
SUBCOMMANDS = set(build_parser()._subparsers._group_actions[0].choices)  # type: ignore[union-attr]


def fenced_commands() -> list[tuple[str, str]]:
    """(where, command) of every cdprctl line in a fenced block; shell variables set in the
    block (``Z="..."``) substituted, comments and continuation lines joined."""
    out = []
    for doc in DOCS:
        fenced, in_block, env, pending = False, False, {}, ""
        for n, raw in enumerate(doc.read_text().splitlines(), 1):
            if raw.lstrip().startswith("```"):
                fenced = not fenced
                in_block = fenced and raw.strip()[3:] in ("", "sh", "bash", "shell", "console")
                env, pending = {}, ""
                continue
            if not in_block or re.search("[─│├└┌┐┘┬┴▶►]", raw):  # a diagram, not a shell
                continue
            line = pending + raw.split(" #", 1)[0].rstrip()
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            pending = ""
            m = re.fullmatch(r"\s*([A-Z_]+)=\"([^\"]*)\"", line)
            if m:
                env[m.group(1)] = m.group(2)
                continue
            m = re.match(r"\s*(?:\.venv/bin/)?cdprctl\s+(.*)", line)
            if m:
                text = m.group(1)
                for k, v in env.items():
                    text = text.replace(f"${k}", v)
                out.append((f"{doc.relative_to(ROOT)}:{n}", text))
        # and in the prose: `cdprctl ...` spans (a span may wrap a line), whole commands only
        text = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)
        for m in re.finditer(r"`(?:\.venv/bin/)?cdprctl ([^`]+)`", text):
            span = " ".join(m.group(1).split())
            words = span.split()
            synopsis = re.search(r"[\[<…]|\.\.\.", span) or any(
                w.isalpha() and w.isupper() for w in words  # --rate R, --config FILE
            )
            if synopsis or words[0] not in SUBCOMMANDS or len(words) < 4:
                continue  # a synopsis, a name or an excerpt (`cdprctl run --path`)
            line = text.count("\n", 0, m.start()) + 1
            out.append((f"{doc.relative_to(ROOT)}:{line}", span))
    return out


COMMANDS = fenced_commands()


def test_the_docs_have_commands_to_check():
    assert len(COMMANDS) > 30


@pytest.mark.parametrize("where, text", COMMANDS, ids=[w for w, _ in COMMANDS])
def test_a_documented_command_is_taken_as_written(where, text, capsys):
    argv = shlex.split(text)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:
        if exc.code == 0:  # --help
            return
        pytest.fail(f"{where}: cdprctl {text}: {capsys.readouterr().err.strip()}")
    if argv[0] in ZENOH_TOOLS:
        assert args.robot or args.prefix, f"{where}: cdprctl {text}: give --robot or --prefix"
    for opt, value in itertools.pairwise(argv):
        if opt in FILE_OPTIONS and not value.startswith(("/", "$", "~")) and "/" in value:
            if any(p in value for p in ("robot.toml", "my_", "FILE", "runs/")):
                continue  # a placeholder for the user's own file
            assert (ROOT / value).exists(), f"{where}: {opt} {value}: no such file here"


#: sub-commands that need no robot, no daemon and no recording: run as documented
OFFLINE = {"check-config", "tda", "bus-load", "workspace", "path"}
RUNNABLE = [(w, t) for w, t in COMMANDS if shlex.split(t)[0] in OFFLINE]


def test_the_docs_have_commands_to_run():
    assert len(RUNNABLE) >= 8


@pytest.mark.parametrize("where, text", RUNNABLE, ids=[w for w, _ in RUNNABLE])
def test_a_documented_offline_command_runs_as_written(where, text, tmp_path, monkeypatch,
                                                      capsys):  # fmt: skip
    """Run, not only parsed: from a directory like a checkout's (its config/, paths/ and the
    tests' example files), so what it writes (plots) lands in a temporary one; exit 0, no
    traceback, what it says it wrote is there."""
    from cdprctl.cli import main

    for d in ("config", "paths", "tests/data"):
        (tmp_path / d).parent.mkdir(exist_ok=True)
        (tmp_path / d).symlink_to(ROOT / d)
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(text)
    try:
        code = main(argv)
    except SystemExit as exc:  # --help
        code = int(exc.code or 0)
    out = capsys.readouterr()
    assert code == 0, f"{where}: cdprctl {text}:\n{out.err}"
    assert "Traceback" not in out.out + out.err
    for opt, value in itertools.pairwise(argv):
        if opt == "--plot":
            made = list(tmp_path.glob(f"{value}*"))
            assert made, f"{where}: --plot {value}: nothing written"


#: the documented moves, in order: (where, robot, the ``send`` line's fields)
MOVES = [
    (w, shlex.split(t)[shlex.split(t).index("--robot") + 1], shlex.split(t))
    for w, t in COMMANDS
    if shlex.split(t)[0] == "send" and "move" in shlex.split(t) and "--robot" in shlex.split(t)
]


def test_the_commands_page_shows_a_move():
    assert any(w.startswith("docs/commands.md") for w, _, _ in MOVES), MOVES


@pytest.mark.parametrize("doc", sorted({w.split(":")[0] for w, _, _ in MOVES}))
def test_a_documented_move_is_one_the_gateway_takes(doc):
    """Each documented ``cdprctl send ... move`` as the robot it names (config/<name>.toml)
    would take it once enabled: its fields read as ``send`` reads them, the payload parsed and
    checked by the gateway's own validator with the reference where the page's earlier moves
    left it (home first) — the workspace, the tilt, the tensions and the straight line's soft
    limits. A move the robot would refuse fails here, naming the line and the reason."""
    import json

    import numpy as np

    from cdprctl.commands.zenoh_tools import fields_payload
    from cdprctl.core.rotation import rpy_to_matrix
    from cdprctl.motion.trajectory import pose_coordinates
    from cdprctl.robot_file import load_robot
    from cdprctl.telemetry.zenoh.validate import CommandError, CommandValidator

    reference: dict[str, np.ndarray] = {}
    for where, robot, argv in (m for m in MOVES if m[0].startswith(doc + ":")):
        path = ROOT / "config" / f"{robot.replace('-', '_')}.toml"
        assert path.exists(), f"{where}: no config/{path.name} for --robot {robot}"
        model = load_robot(path)
        gateway = CommandValidator(model, commands_enabled=True)
        home = pose_coordinates(model, model.home.position, model.home.rotation)
        fields = fields_payload(argv[argv.index("move") + 1 :])
        payload = gateway.parse(json.dumps(fields).encode(), "move")
        try:
            _, out = gateway.check("move", payload, "enabled",
                                   {"reference": reference.get(robot, home)})  # fmt: skip
        except CommandError as exc:
            pytest.fail(f"{where}: cdprctl {' '.join(argv)}: refused: {exc}")
        pose = np.asarray(out["pose"], dtype=float)
        reference[robot] = pose_coordinates(model, pose[:3], rpy_to_matrix(*pose[3:]))
