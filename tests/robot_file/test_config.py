"""Every rule of the robot description with a broken file: the error names the file, the key,
the value, the unit and the rule; all errors of a file are reported; no model escapes."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from conftest import CONFIG, without_table

from cdprctl.cli import main
from cdprctl.model import ConfigError
from cdprctl.robot_file import load_robot

BASE = without_table((CONFIG / "rowc.toml").read_text(), "drives")


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def sub(pattern: str, repl: str, text: str = BASE, count: int = 1) -> str:
    new, n = re.subn(pattern, repl, text, count=count, flags=re.M)
    assert n >= 1, f"pattern {pattern!r} not in the base file"
    return new


def errors_of(tmp_path: Path, text: str) -> list[str]:
    p = write(tmp_path, text)
    with pytest.raises(ConfigError) as exc:
        load_robot(p)
    for e in exc.value.errors:
        assert e.startswith(str(p) + ": "), e
    return exc.value.errors


CASES = [
    # (id, broken text, substrings expected in one error message)
    (
        "tmin>tmax",
        sub(r"^tension_min = 10.0", "tension_min = 250.0"),
        ["cables[0].tension_min = 250 N exceeds tension_max = 200 N"],
    ),
    (
        "negative tmin",
        sub(r"^tension_min = 10.0", "tension_min = -1.0"),
        ["cables[0].tension_min = -1 N must be >= 0"],
    ),
    (
        "negative modulus",
        sub(r"^youngs_modulus = 80.0e9", "youngs_modulus = -80.0e9"),
        ["cables[0].youngs_modulus = -8e+10 Pa must be > 0"],
    ),
    (
        "nan stiffness",
        sub(r"^youngs_modulus = 80.0e9  # Pa\ncross_section = 0.75e-6", "stiffness = nan"),
        ["cables[0].stiffness = nan N/m must be finite"],
    ),
    ("inf mass", sub(r"^mass = 8.0", "mass = inf"), ["platform.mass = inf kg must be finite"]),
    ("zero mass", sub(r"^mass = 8.0", "mass = 0.0"), ["platform.mass = 0 kg must be > 0"]),
    (
        "missing mass",
        sub(r"^mass = 8.0.*\n", ""),
        ["platform.mass is missing: required, a number (unit: kg)"],
    ),
    (
        "mass as string",
        sub(r"^mass = 8.0", 'mass = "8"'),
        ["platform.mass = '8' must be a number in kg"],
    ),
    (
        "anchor wrong shape",
        sub(r"^anchor = \[0.050, 0.250, 0.000\]", "anchor = [0.05, 0.25]"),
        ["cables[0].anchor = [0.05, 0.25] must be a list of 3 numbers (m)"],
    ),
    (
        "anchor missing",
        sub(r"^anchor = \[0.050, 0.250, 0.000\].*\n", ""),
        ["cables[0].anchor is missing"],
    ),
    (
        "both elasticities",
        sub(r"^cross_section = 0.75e-6", "cross_section = 0.75e-6\nstiffness = 1e4"),
        ["cables[0] gives both stiffness and youngs_modulus/cross_section"],
    ),
    (
        "no elasticity",
        sub(r"^youngs_modulus = 80.0e9  # Pa\ncross_section = 0.75e-6.*\n", ""),
        ["cables[0].stiffness is missing"],
    ),
    (
        "modulus without section",
        sub(r"^cross_section = 0.75e-6.*\n", ""),
        ["cables[0].cross_section is missing"],
    ),
    (
        "duplicate names",
        sub(r'^name = "2"', 'name = "1"'),
        ["cables[1].name = '1' duplicates the name of cables[0]"],
    ),
    (
        "unknown key",
        sub(r"^tension_min = 10.0", "tension_min = 10.0\ntensoin_max = 3"),
        ["cables[0].tensoin_max is not a known key (did you mean tension_max? allowed"],
    ),
    ("unknown top", BASE + "\nfoo = 1\n", ["foo is not a known key (allowed here:"]),
    (
        "winch too weak",
        sub(r"^torque_limit = 2.6", "torque_limit = 1.0"),
        ["cables[0].tension_max = 200 N exceeds what the winch can hold"],
    ),
    (
        "bad encoder",
        sub(r"^encoder_counts_per_rev = 65536", "encoder_counts_per_rev = 12.5"),
        ["winch.encoder_counts_per_rev = 12.5 counts must be an integer"],
    ),
    (
        "negative drum",
        sub(r"^drum_radius = 0.045", "drum_radius = -0.045"),
        ["winch.drum_radius = -0.045 m must be > 0"],
    ),
    (
        "inertia not PD",
        sub(r"^inertia = \[0.05, 0.05, 0.06\]", "inertia = [0.05, -0.05, 0.06]"),
        ["platform.inertia", "must be positive definite"],
    ),
    (
        "inertia not physical",
        sub(r"^inertia = \[0.05, 0.05, 0.06\]", "inertia = [0.01, 0.01, 0.06]"),
        ["platform.inertia", "triangle inequality"],
    ),
    (
        "inertia asymmetric",
        sub(
            r"^inertia = \[0.05, 0.05, 0.06\]",
            "inertia = [[0.05, 0.01, 0], [0, 0.05, 0], [0, 0, 0.06]]",
        ),
        ["platform.inertia", "must be symmetric"],
    ),
    (
        "home outside workspace",
        sub(r"^position = \[1.5, 0.35, 0.59\]", "position = [2.9, 0.35, 0.59]"),
        ["home.position[0] = 2.9 m is outside the workspace [0.5, 2.5] m (x)"],
    ),
    (
        "workspace inverted",
        sub(r"^position_min = \[0.5,", "position_min = [2.7,"),
        ["workspace.position_min[0] = 2.7 m must be < position_max[0] = 2.5 m (x)"],
    ),
    (
        "home not feasible",
        sub(r"^mass = 8.0", "mass = 80.0"),
        ["home pose: no tensions within [tension_min, tension_max] hold the platform's weight"],
    ),
    (
        "too few cables",
        "[[cables]]".join(BASE.split("[[cables]]")[:5]),
        ["cables has 4 entries: a 6-DOF platform needs at least 6 cables"],
    ),
    (
        "pulley zero axis",
        sub(
            r"^cross_section = 0.75e-6.*$",
            "cross_section = 0.75e-6\n[cables.pulley]\nradius = 0.02\naxis = [0.0, 0.0, 0.0]",
        ),
        ["cables[0].pulley.axis = [0, 0, 0] must not be the zero vector"],
    ),
    (
        "gravity not vector",
        sub(r"^gravity = .*$", "gravity = -9.81"),
        ["gravity = -9.81 m/s² must be a list of 3 numbers (m/s²)"],
    ),
    ("not toml", "name = \n", ["not valid TOML"]),
]


CASES.append(
    (
        "negative stiffness",
        sub(r"^youngs_modulus = 80.0e9  # Pa\ncross_section = 0.75e-6", "stiffness = -1000.0"),
        ["cables[0].stiffness = -1000 N/m must be > 0"],
    )
)


@pytest.mark.parametrize("text,expected", [(c[1], c[2]) for c in CASES], ids=[c[0] for c in CASES])
def test_bad_file_gets_a_clear_error(tmp_path, text, expected):
    errors = errors_of(tmp_path, text)
    joined = "\n".join(errors)
    assert any(all(s in e for s in expected) for e in errors), joined


def test_all_errors_of_a_file_are_collected(tmp_path):
    text = sub(r"^mass = 8.0", "mass = -3.0")
    text = sub(r"^tension_min = 10.0", "tension_min = 300.0", text)
    text = sub(r"^drum_radius = 0.045", "drum_radius = nan", text)
    text = sub(r'^name = "3"', 'name = "1"', text)
    errors = errors_of(tmp_path, text)
    assert len(errors) >= 4, errors
    for needle in ("platform.mass", "cables[0].tension_min", "winch.drum_radius", "cables[2].name"):
        assert any(needle in e for e in errors), (needle, errors)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="cannot read the file"):
        load_robot(tmp_path / "nope.toml")


def test_model_is_frozen(rowc):
    import dataclasses

    with pytest.raises(dataclasses.FrozenInstanceError):
        rowc.name = "x"  # type: ignore[misc]
    with pytest.raises(ValueError):
        rowc.anchors[0, 0] = 1.0


def test_check_config_cli_summary_and_errors(tmp_path, capsys, monkeypatch):
    assert main(["check-config", str(CONFIG / "seed000.toml")]) == 0
    out = capsys.readouterr().out
    assert "cables      8 (redundancy r = 2)" in out
    assert "mass 150 kg" in out
    # the 8 cable lengths at home are printed, cable 1 is 6.4 m long or so
    assert re.search(r"^\s+1\s+50\.0\s+800\.0\s+\d\.\d{4}", out, flags=re.M)
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    assert main(["check-config", str(CONFIG / "seed000.toml")]) == 0
    assert ("ros2        off (cdprctl run --ros2 turns it on); domain 7, topics under "
            "/cdpr/seed000 at 50 Hz (docs/ros2.md)") in capsys.readouterr().out
    monkeypatch.setenv("ROS_DOMAIN_ID", "x")
    assert main(["check-config", str(CONFIG / "seed000.toml")]) == 0
    assert "; ROS_DOMAIN_ID = 'x' is not a ROS 2 domain" in capsys.readouterr().out
    bad = write(tmp_path, sub(r"^mass = 8.0", "mass = -1.0"))
    assert main(["check-config", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "platform.mass = -1 kg must be > 0" in err


def test_every_shipped_config_loads():
    for p in sorted(CONFIG.glob("*.toml")):
        load_robot(p)


DRIVES = """
[drives]
driver = "cia402"
rated_torque = 2.6
[[drives.buses]]
interface = "socketcan"
channel = "can0"
cables = ["1", "2", "3", "4"]
node_ids = [1, 2, 3, 4]
[[drives.buses]]
interface = "socketcan"
channel = "can1"
cables = ["5", "6", "7", "8"]
node_ids = [1, 2, 3, 4]
"""


def test_drives_section_two_buses(tmp_path):
    from cdprctl.robot_file import load_robot

    model = load_robot(write(tmp_path, BASE + DRIVES, "ok.toml"))
    assert [b.channel for b in model.drives.buses] == ["can0", "can1"]
    assert model.drives.node_of(5) == (1, 2)


@pytest.mark.parametrize(
    "change,expected",
    [
        (
            ("node_ids = [1, 2, 3, 4]\n[[drives", "node_ids = [1, 2, 2, 4]\n[[drives"),
            "drives.buses[0].node_ids = [1, 2, 2, 4] repeats node id 2",
        ),
        (
            ('cables = ["5", "6", "7", "8"]', 'cables = ["5", "6", "7", "9"]'),
            "drives.buses[1].cables = '9' is not a cable",
        ),
        (
            ('cables = ["5", "6", "7", "8"]', 'cables = ["5", "6", "7", "1"]'),
            "drives.buses[1].cables = '1' is already on drives.buses[0]",
        ),
        (
            ('cables = ["5", "6", "7", "8"]', 'cables = ["5", "6", "7"]'),
            "drives.buses[1].node_ids = [1, 2, 3, 4] must be a list of integers, one per cable",
        ),
        (
            ('driver = "cia402"', 'driver = "ethercat"'),
            "drives.driver = 'ethercat' must be one of cia402, odrive",
        ),
        (("rated_torque = 2.6", "rated_torque = -1"), "drives.rated_torque = -1 N·m must be > 0"),
        (
            ("node_ids = [1, 2, 3, 4]\n[[drives", "node_ids = [1, 2, 3, 127]\n[[drives"),
            "contains the controller's node id 127",
        ),
        (
            ('channel = "can0"', 'channel = "can0"\ndcf = "winch.dcf"'),
            "drives.buses[0].dcf = 'winch.dcf' no such file",
        ),
        (
            ('channel = "can0"', 'channel = "can0"\ndcf = ["a.dcf", ""]'),
            "must list one file per drive of the bus (4)",
        ),
        (
            ('driver = "cia402"', 'driver = "cia402"\npdo_mapping = "auto"'),
            "drives.pdo_mapping = 'auto' must be 'configure'",
        ),
    ],
)
def test_drives_section_errors(tmp_path, change, expected):
    text = (BASE + DRIVES).replace(*change)
    errors = errors_of(tmp_path, text)
    assert any(expected in e for e in errors), errors


@pytest.mark.parametrize("text,expected", [(c[1], c[2]) for c in CASES], ids=[c[0] for c in CASES])
def test_no_broken_file_starts_the_loop(tmp_path, capsys, text, expected):
    """`cdprctl run` on each broken file of the corpus: exit code 1, the error on stderr,
    and the loop never starts (no "ready:", no drive opened)."""
    p = write(tmp_path, text)
    assert main(["run", "--config", str(p), "--sim", "--no-realtime", "--duration", "1"]) == 1
    out = capsys.readouterr()
    assert any(all(x in line for x in expected) for line in out.err.splitlines()), out.err
    assert "ready:" not in out.out and "cycles" not in out.out


def test_drive_mode_keys(tmp_path):
    """``[drives] mode`` names the mode and the rule; position mode needs CiA 402 drives; a
    ``[drives]`` table without buses keeps the default simulated bus."""
    errs = errors_of(tmp_path, BASE + '\n[drives]\nmode = "cps"\n')
    assert any("drives.mode" in e and "cps" in e and "cst, csp" in e for e in errs), errs
    errs = errors_of(tmp_path, BASE + '\n[drives]\ndriver = "odrive"\nmode = "csp"\n')
    assert any("drives.torque_constant is missing" in e and "8.27 / KV" in e and "N·m/A" in e
               and "mode = 'cst'" in e for e in errs), errs
    errs = errors_of(tmp_path, BASE + "\n[drives]\nposition_loop_bandwidth = -5\n")
    assert any("drives.position_loop_bandwidth" in e and "Hz" in e for e in errs), errs
    errs = errors_of(tmp_path, BASE + "\n[drives]\nfollowing_error_window = 0\n")
    assert any("drives.following_error_window" in e and " m" in e for e in errs), errs
    errs = errors_of(tmp_path, BASE + "\n[drives]\nfollowing_error_timeout = 70\n")
    assert any("drives.following_error_timeout" in e and "65.535" in e for e in errs), errs
    for bad, rule in (("0.009", ">= 0.01"), ("0", ">= 0.01"), ("328", "<= 327.675")):
        errs = errors_of(tmp_path, BASE + f"\n[drives]\nheartbeat_timeout = {bad}\n")
        assert any(f"drives.heartbeat_timeout = {bad} s must be {rule}" in e for e in errs), errs
    for ok in (0.01, 327.675):  # 2 ms and 65535 ms between the drives' heartbeats
        text = BASE + f"\n[drives]\nheartbeat_timeout = {ok}\n"
        assert load_robot(write(tmp_path, text, "h.toml")).drives.heartbeat_timeout == ok
    for bad, rule in (("-0.01", ">= 0"), ("2", "<= 1")):
        errs = errors_of(tmp_path, BASE + f"\n[drives]\nbrake_release_time = {bad}\n")
        assert any("drives.brake_release_time" in e and " s" in e and rule in e for e in errs)
    model = load_robot(write(tmp_path, BASE + '\n[drives]\nbrake_release_time = 0\n', "z.toml"))
    assert model.drives.brake_release_time == 0.0
    model = load_robot(write(tmp_path, BASE + '\n[drives]\nmode = "csp"\n', "ok.toml"))
    assert model.drives.brake_release_time == 0.05
    assert model.drives.mode == "csp" and len(model.drives.buses) == 1
    assert model.drives.buses[0].cables == tuple(range(model.n_cables))


def test_drive_mode_by_default(tmp_path):
    """Where the file does not say, position mode (every gain from the model), with either
    driver (an ODrive's needs the motors' torque constant). A gripper's drive stays in torque
    mode either way (its cable's tension squeezes the jaw)."""
    assert load_robot(write(tmp_path, BASE, "plain.toml")).drives.mode == "csp"
    text = BASE + '\n[drives]\ndriver = "odrive"\ntorque_constant = 0.0827\n'
    odrive = load_robot(write(tmp_path, text, "od.toml"))
    assert odrive.drives.mode == "csp" and odrive.drives.torque_constant == 0.0827
    d = load_robot(CONFIG / "seed000_grippers.toml").drives  # it does not say
    assert d.mode == "csp" and d.torque_cables == (0, 7)
    assert [d.mode_of(c) for c in range(8)] == ["cst"] + ["csp"] * 6 + ["cst"]
    torque = dataclasses.replace(d, mode="cst")
    assert [torque.mode_of(c) for c in range(8)] == ["cst"] * 8


def with_key(table: str, line: str) -> str:
    """BASE with ``line`` in ``[table]``: in place of the key's own line where the file sets
    it, else at the top of the table (added when the file has none)."""
    key = line.split(" = ")[0]
    if re.search(rf"^{key} = ", BASE, re.M):
        return sub(rf"^{key} = .*$", line)
    header = f"[{table}]"
    if re.search(rf"^{re.escape(header)}", BASE, re.M):
        return sub(rf"^{re.escape(header)}.*$", f"{header}\n{line}")
    return f"{BASE}\n{header}\n{line}\n"


@pytest.mark.parametrize(
    ("table", "line", "expected"),
    [
        ("control", "rate = 20000.0", "control.rate = 20000 Hz must be <= 10000"),
        # degrees typed for radians (a newcomer's 11.5 for 11.5°): named as such
        ("workspace", "max_angle = 11.5", "workspace.max_angle = 11.5 rad must be <= 3.14159 "
         "rad (did you mean degrees? 11.5° = 0.2007 rad)"),
        ("home", "rpy = [0.0, 0.0, 30.0]", "home.rpy = [0, 0, 30] must be within ±pi rad each "
         "(did you mean degrees? 30° = 0.5236 rad)"),
        ("control", "disturbance_bandwidth = 50.0",
         "control.disturbance_bandwidth = 50 Hz must be <= 5"),
        ("control", "force_feedback = 11.0",
         "control.force_feedback = 11 × the lowest mode must be <= 10"),
        ("control", "jog_deadman = 6.0", "control.jog_deadman = 6 s must be <= 5"),
        ("control.tda", "nu = 1.5", "control.tda.nu = 1.5 must be <= 1"),
        ("control.safety", "max_tension_disagreement = 3.0",
         "control.safety.max_tension_disagreement = 3 of the tension range must be <= 1"),
        ("control.realtime", "sleep_margin = 0.02",
         "control.realtime.sleep_margin = 0.02 s must be <= 0.01"),
        ("control.realtime", "sched_priority = 100",
         "control.realtime.sched_priority = 100 must be <= 99"),
    ],
    ids=lambda v: v if isinstance(v, str) and "=" not in v else None,
)
def test_every_bounded_control_setting_refuses_a_value_above_its_bound(
    tmp_path, table, line, expected
):
    """The upper bounds a setting's rule names (a disagreement beyond the whole tension range
    would never find a slipped cable; an observer beyond 5 Hz meets the platform's modes)."""
    errors = errors_of(tmp_path, with_key(table, line))
    assert any(expected in e for e in errors), errors
