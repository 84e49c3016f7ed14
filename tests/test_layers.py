"""The import layers (docs/architecture.md): a module imports only from its own layer or the
layers below, wherever the import stands (function bodies included). Read from the source with
``ast``: nothing is imported to check it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from import_graph import circles, imports_within, modules_under

ROOT = Path(__file__).resolve().parents[1]

# bottom → top; the first prefix that matches a module names its layer; each layer is a
# package of cdprctl (or the few packages named), as docs/architecture.md's "Layers" table
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("core", ("cdprctl.core",)),
    ("model", ("cdprctl.model",)),
    ("geometry", ("cdprctl.geometry",)),
    ("robot file", ("cdprctl.robot_file",)),  # the loader checks a robot with the geometry
    ("tda", ("cdprctl.tda",)),
    ("motion", ("cdprctl.motion",)),
    ("hardware", ("drivers", "sim_backend")),
    ("control", ("cdprctl.control",)),
    ("services", ("cdprctl.experiments", "cdprctl.telemetry", "cdprctl.daemon",
                  "cdprctl.calibration", "cdprctl.safety")),
    ("commands", ("cdprctl.commands", "cdprctl.cli")),
]
EXACT = {"cdprctl": 0}  # the package itself: its version string
# the telemetry sees the control layer only through its data and command definitions
TELEMETRY_MAY_USE = ("cdprctl.control.data", "cdprctl.control.command_types",
                     "cdprctl.control.states")


def layer_of(module: str) -> int | None:
    if module in EXACT:
        return EXACT[module]
    for i, (_, prefixes) in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return i
    return None


def modules() -> list[tuple[str, Path]]:
    out = []
    for pkg in ("cdprctl", "drivers", "sim_backend"):
        for f in sorted((ROOT / pkg).rglob("*.py")):
            rel = f.relative_to(ROOT).with_suffix("")
            name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
            out.append((name, f))
    return out


def imports_of(module: str, path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    out = []
    pkg = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the package
                parts = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            out += [f"{base}.{a.name}" if layer_of(f"{base}.{a.name}") is not None else base
                    for a in node.names]  # fmt: skip
    return [m for m in out if layer_of(m) is not None]


def test_every_module_has_a_layer():
    assert [m for m, _ in modules() if layer_of(m) is None] == []


@pytest.mark.parametrize("module,path", modules(), ids=[m for m, _ in modules()])
def test_imports_point_down(module, path):
    mine = layer_of(module)
    assert mine is not None
    up = []
    for imp in imports_of(module, path):
        theirs = layer_of(imp)
        assert theirs is not None
        if theirs > mine:
            up.append(f"{imp} ({LAYERS[theirs][0]} above {LAYERS[mine][0]})")
        telemetry = module.startswith("cdprctl.telemetry")
        control = imp.startswith("cdprctl.control")
        if telemetry and control and not imp.startswith(TELEMETRY_MAY_USE):
            up.append(f"{imp} (telemetry may use only {', '.join(TELEMETRY_MAY_USE)})")
        if telemetry and imp.startswith("cdprctl.daemon"):  # the daemon uses the telemetry
            up.append(f"{imp} (the telemetry runs beside the daemon, never on it)")
    assert up == [], f"{module} imports upwards: {up}"


def test_the_checker_sees_the_telemetry_import_the_daemon(tmp_path, monkeypatch):
    """The rule within the services layer can fail too: a planted import of the daemon from
    a telemetry module is reported."""
    f = tmp_path / "x.py"
    f.write_text("def f():\n    from cdprctl.daemon.service import Daemon\n")
    monkeypatch.setattr(
        "test_layers.imports_of", lambda module, path: ["cdprctl.daemon.service.Daemon"]
    )
    with pytest.raises(AssertionError, match="runs beside the daemon"):
        test_imports_point_down("cdprctl.telemetry.x", f)


def test_the_checker_sees_an_upward_import(tmp_path):
    """The check itself can fail: a driver importing the controller is caught."""
    f = tmp_path / "x.py"
    f.write_text("def f():\n    from cdprctl.control.cycle.controller import Controller\n")
    imps = imports_of("drivers.x", f)
    assert imps == ["cdprctl.control.cycle.controller.Controller"]
    assert layer_of(imps[0]) > layer_of("drivers.x")


def test_the_controller_sees_a_view_of_the_drives_not_the_driver():
    """The manager owns the driver; the controller and the supervisor get a ``DriveView``:
    the lifecycle, its error, the feedback and the lifecycle requests — no read, no write, no
    bus (ros2_control's state and command interfaces, not the hardware object)."""
    from cdprctl.control.lifecycle.drive_view import DriveView
    from cdprctl.control.lifecycle.manager import ControllerManager
    from cdprctl.robot_file import load_robot
    from sim_backend.network import LockStep

    model = load_robot(ROOT / "config" / "rowc.toml")
    rig = LockStep(model, period=model.control.period)
    try:
        manager = ControllerManager(model, rig.driver)
        view = manager.controller.drives
        assert isinstance(view, DriveView) and manager.controller.supervisor.drives is view
        assert view.states is rig.driver.states and view.lifecycle is rig.driver.lifecycle
        for name in ("read", "write", "configure", "shutdown", "buses", "model"):
            assert not hasattr(view, name), name
    finally:
        rig.close()


def test_the_architecture_doc_holds_the_same_layers():
    """docs/architecture.md's "Layers" table names, row by row, the packages of ``LAYERS``."""
    doc = (ROOT / "docs" / "architecture.md").read_text()
    table = doc.split("## Layers", 1)[1].split("\n\n")[2]
    rows = [r.split("|")[1:3] for r in table.splitlines()[2:]]
    in_doc = [(name.strip(), tuple(sorted(
        p.strip(" `/").removesuffix(".py").replace("/", ".") for p in cell.split(", ")
    ))) for name, cell in rows]  # fmt: skip
    assert in_doc == [(name, tuple(sorted(prefixes))) for name, prefixes in LAYERS]


def test_no_module_stands_loose_beside_the_layers_packages():
    """A module of cdprctl/ belongs to a layer's package; only the entry point (``cli.py``)
    and the package's face stand at its top."""
    loose = sorted(f.name for f in (ROOT / "cdprctl").glob("*.py"))
    assert loose == ["__init__.py", "cli.py"]


def test_the_tree_imports_without_a_circle():
    """No module imports, through others, itself — under ``TYPE_CHECKING`` and in function
    bodies too (a late import hides a circle; it does not remove it)."""
    mods = modules_under(ROOT, "cdprctl", "drivers", "sim_backend")
    graph = {name: imports_within(name, path, set(mods)) for name, path in mods.items()}
    assert "cdprctl.geometry.kinematics" in graph["cdprctl.control.cycle.estimator"]
    assert circles(graph) == []


def test_the_circle_check_sees_a_late_and_a_type_only_import(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from pkg.b import g\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from pkg import a\n")  # fmt: skip
    mods = modules_under(tmp_path, "pkg")
    graph = {name: imports_within(name, path, set(mods)) for name, path in mods.items()}
    assert circles(graph) == [["pkg.a", "pkg.b"]]
