"""Convert the CASPR-derived robot JSON files of ../shared/robots/ into cdprctl TOML files.

Run once by hand (``python tools/convert_caspr_json.py ../shared/robots config``); the TOML files
it writes are committed. The CASPR models are rigid ("cable_ideal") and carry no winch data: the
elasticity and winch values below are assumptions, said so in the files.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ASSUMED = {
    "caroca": {
        "file": "caroca_caspr.json",
        "youngs_modulus": 100e9,  # steel wire rope, effective modulus (assumed)
        "cross_section": 1.26e-5,  # 4 mm rope (assumed)
        "winch": dict(
            drum_radius=0.05,
            gear_ratio=10.0,
            rotor_inertia=2.0e-4,
            viscous_friction=1.0e-3,
            coulomb_friction=0.05,
            torque_limit=10.0,
            encoder_counts_per_rev=131072,
        ),
        "workspace": ([-2.5, -2.0, 0.3], [2.5, 2.0, 2.5], 0.6),
    },
    "cogiro": {
        "file": "cogiro_caspr.json",
        "youngs_modulus": 100e9,
        "cross_section": 2.83e-5,  # 6 mm rope (assumed)
        "winch": dict(
            drum_radius=0.1,
            gear_ratio=20.0,
            rotor_inertia=1.0e-3,
            viscous_friction=5.0e-3,
            coulomb_friction=0.2,
            torque_limit=30.0,
            encoder_counts_per_rev=131072,
        ),
        "workspace": ([-5.0, -3.5, 0.5], [5.0, 3.5, 4.5], 0.5),
    },
}


WINCH_UNITS = {
    "drum_radius": "m",
    "gear_ratio": "motor turns per drum turn",
    "rotor_inertia": "kg·m² at the motor",
    "viscous_friction": "N·m·s/rad at the motor",
    "coulomb_friction": "N·m at the motor",
    "torque_limit": "N·m, motor",
    "encoder_counts_per_rev": "counts per motor turn",
}


def fmt(x: object) -> str:
    if isinstance(x, float):
        return repr(float(x))
    if isinstance(x, int):
        return str(x)
    if isinstance(x, list):
        return "[" + ", ".join(fmt(v) for v in x) + "]"
    if isinstance(x, str):
        return json.dumps(x)
    raise TypeError(x)


def convert(key: str, src_dir: Path, cable_set: str | None, out: Path) -> None:
    spec = ASSUMED[key]
    d = json.loads((src_dir / spec["file"]).read_text())
    cables = d["cables"] if cable_set is None else d["cable_sets"][cable_set]
    pf = d["platform"]
    lo, hi, ang = spec["workspace"]
    name = key if cable_set is None else f"{key}_pulleys"
    lines = [
        f"# {d['name']}" + ("" if cable_set is None else f" — cable set '{cable_set}'"),
        f"# Source: {d['source']['repo']} @ {d['source']['commit']}",
        *[f"#   {p}" for p in d["source"]["paths"]],
        "# converted from ../shared/robots/" + spec["file"] + " by tools/convert_caspr_json.py.",
        "# Geometry, mass, inertia and tension limits are the source's. The source models rigid",
        "# cables and has no winch data: youngs_modulus, cross_section and [winch] are ASSUMED",
        "# plausible values, not measured ones.",
        f"# CASPR pose convention {pf['joint_type']} (XYZ Euler); the home orientation is zero,",
        "# so it equals cdprctl's roll-pitch-yaw.",
        "",
        f"name = {fmt(name)}",
        f"source = {fmt(d['source']['repo'] + '@' + d['source']['commit'][:12])}",
        "gravity = [0.0, 0.0, -9.81]  # m/s², base frame",
        "",
        "[platform]",
        f"mass = {fmt(pf['mass_kg'])}  # kg",
        f"com = {fmt(pf['com_location'])}  # m, platform frame",
        "inertia = [  # kg·m², about the COM, platform frame",
        *[f"  {fmt(row)}," for row in pf["inertia_kgm2"]],
        "]",
        "",
        "[home]",
        f"position = {fmt(pf['q_initial'][:3])}  # m",
        f"rpy = {fmt(pf['q_initial'][3:])}  # rad",
        "",
        "[workspace]  # assumed: a box inside the frame",
        f"position_min = {fmt(lo)}  # m",
        f"position_max = {fmt(hi)}  # m",
        f"max_angle = {fmt(ang)}  # rad",
        "",
        "[winch]  # ASSUMED",
        *[f"{k} = {fmt(v)}  # {WINCH_UNITS[k]}" for k, v in spec["winch"].items()],
    ]
    for c in cables:
        lines += [
            "",
            "[[cables]]",
            f"name = {fmt(c['name'])}",
            f"anchor = {fmt(c['a'])}  # m, base frame",
            f"attachment = {fmt(c['b'])}  # m, platform frame",
            f"tension_min = {fmt(c['f_min_N'])}  # N",
            f"tension_max = {fmt(c['f_max_N'])}  # N",
            f"youngs_modulus = {fmt(spec['youngs_modulus'])}  # Pa (assumed)",
            f"cross_section = {fmt(spec['cross_section'])}  # m² (assumed)",
        ]
        if "pulley" in c:
            pu = c["pulley"]
            lines += [
                "[cables.pulley]  # CASPR BaseRotatingPulleyAttachment",
                f"radius = {fmt(pu['radius_m'])}  # m",
                f"axis = {fmt(pu['cable_entry_vector'])}",
            ]
    out.write_text("\n".join(lines) + "\n")


def main() -> None:
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    convert("caroca", src, None, dst / "caroca.toml")
    convert("caroca", src, "with_rotating_pulleys", dst / "caroca_pulleys.toml")
    convert("cogiro", src, None, dst / "cogiro.toml")


if __name__ == "__main__":
    main()
