"""``cdprctl tda``: JSON fields, the paper's numbers through the CLI, plots, clear errors."""

from __future__ import annotations

import json

import pytest
from conftest import CONFIG

from cdprctl.cli import main

SEED = str(CONFIG / "seed000.toml")
ROWC = str(CONFIG / "rowc.toml")
SEED_POSE = "7,4,1.5,0.5235987755982988,0,0"


def run_json(capsys, *args):
    code = main(["tda", *args, "--json"])
    return code, json.loads(capsys.readouterr().out)


def test_energy_json_reproduces_sensors_2019(capsys):
    code, r = run_json(capsys, "--config", SEED, "--pose", SEED_POSE, "--wrench",
                       "200,0,0,-0.5,0,0", "--method", "energy",
                       "--impose", "8:energy=100")  # fmt: skip
    assert code == 0
    assert r["status"] == "OK"
    assert r["wrench_residual"] < 1e-9
    assert r["energy_total"] == pytest.approx(407.12, abs=0.005)
    assert r["energy_range"]["1"] == pytest.approx([1.25, 18.36], abs=0.005)
    assert "8" not in r["energy_range"]
    assert len(r["tensions"]) == len(r["energy_per_cable"]) == 8
    assert r["wrench_total_external"] == pytest.approx([200, 0, -1470, -0.5, 0, 0])


@pytest.mark.parametrize(
    "method",
    ["pinv", "closed-form", "barycenter", "sotda", "energy", "qp", "min-2-norm", "min-1-norm"],
)
def test_every_method_from_the_cli(capsys, method, tmp_path):
    png = tmp_path / "p.png"
    code, r = run_json(
        capsys,
        "--config",
        ROWC,
        "--pose",
        "1.5,0.35,0.59,0,0,0",
        "--wrench",
        "0,50,0,0,0,0",
        "--method",
        method,
        "--nu",
        "0.9",
        "--plot",
        str(png),
    )
    assert code == 0 or r["status"] == "OUT_OF_LIMITS"
    assert png.stat().st_size > 10_000
    assert r["method"] == method


def test_energy_line_plot(capsys, tmp_path):
    png = tmp_path / "e.png"
    code = main(["tda", "--config", SEED, "--pose", SEED_POSE, "--wrench", "200,0,0,-0.5,0,0",
                 "--method", "energy", "--impose", "8:deformation=0.4472",
                 "--plot", str(png)])  # fmt: skip
    assert code == 0
    assert png.stat().st_size > 10_000
    assert "plot written" in capsys.readouterr().out


@pytest.mark.parametrize(
    "args,message",
    [
        (["--pose", "1,2,3"], "--pose = '1,2,3': expected six finite numbers x,y,z,roll,pitch,yaw"),
        (["--pose", "7,4,1.5,30,0,0"], "--pose = '7,4,1.5,30,0,0': roll = 30 is taken in "
         "radians and is beyond pi; did you mean degrees? 30° = 0.5236 rad: write it 30deg"),
        (["--pose", "7,4,x,0,0,0"], "--pose = '7,4,x,0,0,0': expected six finite numbers"),
        (["--wrench", "0,0,nan,0,0,0"], "must be finite"),
        (["--method", "energy", "--impose", "9:energy=1"], "no cable '9'"),
        (["--method", "energy", "--impose", "1:power=1"], "quantity must be energy (J)"),
        (
            ["--method", "energy", "--impose", "1:tension=900"],
            "impose cable 1 tension = 900 N is outside [50, 800] N",
        ),
        (["--method", "sotda", "--nu", "2"], "nu = 2.0 must be in [0, 1]"),
    ],
)
def test_bad_arguments_get_clear_errors(capsys, args, message):
    code = main(["tda", "--config", SEED, *args])
    assert code == 2
    assert message in capsys.readouterr().err


def test_a_pose_takes_its_angles_in_degrees_where_they_say_so(capsys):
    """``--pose 7,4,1.5,30deg,0,0`` is the pose of 0.5236 rad (the Sensors 2019 one)."""
    _, in_rad = run_json(capsys, "--config", SEED, "--pose", SEED_POSE, "--wrench",
                         "200,0,0,-0.5,0,0")  # fmt: skip
    _, in_deg = run_json(capsys, "--config", SEED, "--pose", "7,4,1.5,30deg,0,0", "--wrench",
                         "200,0,0,-0.5,0,0")  # fmt: skip
    assert in_deg["tensions"] == pytest.approx(in_rad["tensions"], abs=1e-9)


def test_infeasible_wrench_exit_code(capsys):
    code, r = run_json(capsys, "--config", ROWC, "--wrench", "0,5000,0,0,0,0")
    assert code == 3
    assert r["status"] == "INFEASIBLE"
    assert r["max_violation"] > 0


def test_a_wrench_with_a_minus_first_is_a_value_not_an_option(capsys):
    """``--wrench -30,0,...``: argparse took a list starting with '-' for an option and
    stopped ("expected one argument"); the command line attaches it (cdprctl/cli.py)."""
    code, r = run_json(capsys, "--config", ROWC, "--wrench", "-30,0,0,0,0,0")
    assert code == 0 and r["status"] == "OK"
    code, far = run_json(capsys, "--config", ROWC, "--wrench", "-3000,0,0,0,0,0")
    assert code == 3 and far["status"] == "INFEASIBLE"  # beyond the cables, as any wrench


@pytest.mark.parametrize("argv", [
    ["calibrate", "--config", SEED, "known-pose", "--pose", "7,4,1.5,30,0,0"],
    ["sim", "--config", SEED, "--start-pose", "7,4,1.5,30,0,0"],
])  # fmt: skip
def test_every_pose_a_user_types_takes_degrees_by_one_rule(capsys, argv):
    """``calibrate known-pose --pose`` and ``sim --start-pose`` read a pose as ``tda --pose``
    does (commands/common.pose_or_why): a bare 30 was 30 rad, and known-pose wrote the
    encoders' zeros for that pose without a word. Refused before any bus is opened."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert "roll = 30 is taken in radians and is beyond pi; did you mean degrees? 30° = " \
        "0.5236 rad" in str(exc.value)  # fmt: skip
