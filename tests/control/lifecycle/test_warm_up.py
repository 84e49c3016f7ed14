"""The loop never compiles: every kernel it calls was compiled (or loaded from numba's cache)
by the start-up's warm-up, before the drives started (cdprctl/control/lifecycle/warm_up.py).

Run in a fresh interpreter, where no kernel has been called yet. A kernel's first call in a
process adds a signature to its dispatcher's ``overloads`` (compiled, or loaded from the
cache), so one added during the loop is a kernel the warm-up missed."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

SCRIPT = textwrap.dedent(
    """
    import json, logging, sys
    from pathlib import Path
    import numpy as np
    from numba.core.dispatcher import Dispatcher
    from cdprctl.robot_file import load_robot
    from cdprctl.tda import TDAMethod, TDAOptions
    from cdprctl.experiments.closed_loop import ClosedLoop

    logging.getLogger("cdprctl.drivers").setLevel(logging.ERROR)

    def signatures():
        # signatures of every kernel of cdprctl and drivers (not the simulator's)
        out = {}
        for name, mod in list(sys.modules.items()):
            if mod is None or not name.startswith(("cdprctl", "drivers")):
                continue
            for attr, obj in vars(mod).items():
                if isinstance(obj, Dispatcher):
                    out[f"{name}.{attr}"] = len(obj.overloads)
        return out

    cases = {
        "rowc.toml": (TDAOptions(method=TDAMethod.SOTDA, nu=0.9), [1.8, 0.35, 0.5]),
        "seed000_grippers.toml": (None, [7.05, 4.0, 1.5]),
    }
    out = {}
    for name, (tda, goal) in cases.items():
        model = load_robot(Path("config") / name)
        with ClosedLoop(model, tda) as cl:
            cl.startup()
            before = signatures()
            cl.command("enable")
            cl.run(0.5, record=False)
            cl.command("move", pose=np.concatenate([goal, model.home.rpy]))
            cl.run(1.0, record=False)
            cl.command("set_tda", tda=TDAOptions(method=TDAMethod.BARYCENTER, period=cl.period)
                       if model.redundancy == 2 and not model.grippers else
                       TDAOptions(method=TDAMethod.ENERGY, period=cl.period))
            cl.run(0.5, record=False)
            if model.grippers:
                cl.command("gripper", gripper=0, grip="travel", value=0.1)
                cl.run(0.5, record=False)
            cl.command("stop")
            cl.run(0.5, record=False)
            after = signatures()
            new = sorted(k for k, n in after.items() if n > before.get(k, 0))
            out[name] = {"compiled": new, "kernels": len(before),
                         "state": cl.controller.data.state.value,
                         "cycles": cl.controller.data.cycle}
    print(json.dumps(out))
    """
)


def test_the_loop_compiles_nothing():
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    for name, r in result.items():
        assert r["cycles"] > 500, (name, r)  # the loop ran (3 s: 750 cycles at 250 Hz)
        assert r["kernels"] > 20, (name, r)  # the kernels were found
        assert r["compiled"] == [], f"{name}: compiled in the loop: {r['compiled']}"
