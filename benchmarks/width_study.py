"""Which default friction smoothing width keeps the smoothed model close to exact Coulomb?

For a random family of host + TID systems (``tests/reference/family.py``), the exact
stick-slip steady state (``tests/reference/coulomb.py``) is compared with the steady
state of the tanh-smoothed model (``tests/reference/transient.py``) for several rules
for the width eps [m/s]:

* ``abs``: eps = 1e-4 m/s;
* ``wA/K``: eps = kappa omega A / K (velocity of the static host displacement);
* ``wY``: eps = kappa |omega Y_lin| (inerter-terminal velocity amplitude of the
  frictionless linear steady state, closed form).

For each rule it prints the max and 99th percentile of the relative error of peak |x|
(and of peak |y|) over the cases where the Coulomb reference converged, the number of
such cases, the number of smoothed solves that failed, the max over the family of the
friction stiffness ratio ff / (b eps omega), and the median solve time, as a markdown
table.  Errors of |y| are relative to max(peak |x|, peak |y|) of the Coulomb solution
(a stuck terminal has |y| near 0, so |y| alone is no scale); one column gives the max error of |x| over the
stick-slip cases alone.  ``--friction-scale inerter`` draws ff relative to the
frictionless inerter force instead of the forcing amplitude (see the family module).

    python benchmarks/width_study.py --n 80 --seed 0
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import math
import multiprocessing as mp
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

KAPPAS_A = (0.1, 0.03, 0.01, 0.003, 0.001)
KAPPAS_Y = (0.1, 0.03, 0.01, 0.003, 0.001)
ABS_WIDTH = 1e-4


def rules(kappas_a=KAPPAS_A, kappas_y=KAPPAS_Y):
    """List of (name, kind, value) width rules."""
    out = [(f"abs {ABS_WIDTH:g} m/s", "abs", ABS_WIDTH)]
    out += [(f"wA/K, kappa={k:g}", "wA", k) for k in kappas_a]
    out += [(f"wY_lin, kappa={k:g}", "wY", k) for k in kappas_y]
    return out


def width(case: dict, kind: str, value: float) -> float:
    """Smoothing width eps [m/s] of a rule for one case."""
    from tests.reference.transient import linear_steady_state

    if kind == "abs":
        return value
    if kind == "wA":
        return value * case["omega"] * case["amplitude"] / case["host_stiffness"]
    _, Y = linear_steady_state(case)
    return value * case["omega"] * abs(Y)


def run_case(i: int, case: dict, chosen: list) -> dict:
    """Coulomb reference and all smoothed solves for one case."""
    from tests.reference.coulomb import coulomb_steady_state
    from tests.reference.transient import transient_peaks

    t = time.perf_counter()
    ref = coulomb_steady_state(**case, rtol=1e-10)
    t_ref = time.perf_counter() - t
    out = dict(i=i, ref=dict(x_max=ref["x_max"], y_max=ref["y_max"],
                             converged=ref["converged"], stick=ref["stick_fraction"]),
               t_ref=t_ref, rules={})
    for name, kind, value in chosen:
        eps = width(case, kind, value)
        t = time.perf_counter()
        try:
            r = transient_peaks(case, eps)
        except Exception as exc:  # noqa: BLE001
            r = dict(x_max=math.nan, y_max=math.nan, converged=False, periods=0,
                     steps=0, error=repr(exc))
        r["time"] = time.perf_counter() - t
        r["eps"] = eps
        r["stiff"] = case["friction_force"] / (case["inertance"] * eps * case["omega"])
        out["rules"][name] = r
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=80, help="number of cases")
    ap.add_argument("--seed", type=int, default=0, help="family seed")
    ap.add_argument("--workers", type=int, default=2, help="worker processes")
    ap.add_argument("--kappas", type=float, nargs="+", default=list(KAPPAS_A),
                    help="ratios kappa of the rule eps = kappa omega A / K")
    ap.add_argument("--linear-scale-kappas", type=float, nargs="*", default=list(KAPPAS_Y),
                    help="ratios kappa of the rule eps = kappa |omega Y_lin| (none: skip)")
    ap.add_argument("--json", default=None, help="write the raw results to this file")
    ap.add_argument("--friction-scale", default="amplitude", choices=("amplitude", "inerter"),
                    help="ff ~ U(0, 0.6) x A, or x the frictionless inerter force amplitude")
    args = ap.parse_args()

    from tests.reference.family import family

    cases = family(args.n, args.seed, args.friction_scale)
    chosen = rules(args.kappas, args.linear_scale_kappas)
    t0 = time.perf_counter()
    results = [None] * len(cases)
    ctx = mp.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=args.workers, mp_context=ctx) as ex:
        futs = {ex.submit(run_case, i, c, chosen): i for i, c in enumerate(cases)}
        for n_done, f in enumerate(cf.as_completed(futs), 1):
            r = f.result()
            results[r["i"]] = r
            print(f"[{n_done}/{len(cases)}] case {r['i']} done "
                  f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    wall = time.perf_counter() - t0
    if args.json:
        import json

        with open(args.json, "w") as fh:
            json.dump(dict(cases=cases, results=results), fh, default=float)

    ok_ref = [r for r in results if r["ref"]["converged"]]
    n_stuck = sum(1 for r in ok_ref if r["ref"]["stick"] >= 1.0 - 1e-12)
    n_stickslip = sum(1 for r in ok_ref if 0.0 < r["ref"]["stick"] < 1.0 - 1e-12)
    print(f"family: n={args.n}, seed={args.seed}, friction scale {args.friction_scale}; Coulomb converged {len(ok_ref)}/{len(results)} "
          f"(fully stuck {n_stuck}, stick-slip {n_stickslip}, "
          f"pure slip {len(ok_ref) - n_stuck - n_stickslip}); wall {wall:.0f} s\n")
    print("| rule | max err x | p99 err x | max err x, stick-slip | max err y | p99 err y "
          "| cases | failed | max ff/(b eps w) | median s/solve | max s/solve |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    failed_cases = {}
    for name, _kind, _value in chosen:
        ex_, ey_, exs, fails, stiff, times = [], [], [], 0, [], []
        for r in ok_ref:
            s = r["rules"][name]
            stiff.append(s["stiff"])
            times.append(s["time"])
            if not s["converged"] or not np.isfinite(s["x_max"]):
                fails += 1
                failed_cases.setdefault(name, []).append(r["i"])
                continue
            ref = r["ref"]
            ex_.append(abs(s["x_max"] - ref["x_max"]) / ref["x_max"])
            if 0.0 < ref["stick"] < 1.0 - 1e-12:
                exs.append(ex_[-1])
            ey_.append(abs(s["y_max"] - ref["y_max"]) / max(ref["y_max"], ref["x_max"]))
        ex_, ey_, exs = np.array(ex_), np.array(ey_), np.array(exs)

        def fmt(a, q):
            if a.size == 0:
                return "-"
            return f"{(np.max(a) if q is None else np.percentile(a, q)):.2e}"

        print(f"| {name} | {fmt(ex_, None)} | {fmt(ex_, 99)} | {fmt(exs, None)} | "
              f"{fmt(ey_, None)} | {fmt(ey_, 99)} | {len(ex_)} | {fails} | {max(stiff):.2e} | "
              f"{np.median(times):.2f} | {max(times):.2f} |")
    if failed_cases:
        print("\nfailed smoothed solves (case indices): "
              + "; ".join(f"{k}: {v}" for k, v in failed_cases.items()))


if __name__ == "__main__":
    main()
