"""Exact Coulomb friction (`friction_width=0`) against the smoothed model at its default
width, side by side in one run, both judged against the independent event-driven
stick-slip reference (`tests/reference/coulomb.py`).

Run: `python benchmarks/bench_coulomb.py [--reach N] [--readme benchmarks/README.md]`.
Prints markdown (and, with `--readme`, replaces the `coulomb` block of that file):

- the paper's system on its 61-frequency x 12-amplitude surface: warm time per orbit of
  `frequency_response` (every point in one call) for each model, and each model's
  largest relative error in the peak host and inerter displacements against the
  reference;
- reach: random structures of `tests/reference/family.py` (hosts 0.1-10 Hz, friction up
  to 0.6 of the forcing), exact friction against the reference, one call each.
"""

import argparse
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import tid_jax as tj  # noqa: E402
from benchmarks.bench_steady_state import replace_block  # noqa: E402
from tests.reference.coulomb import coulomb_steady_state  # noqa: E402
from tests.reference.family import family  # noqa: E402

SYSTEM_KEYS = ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
               "tid_stiffness", "tid_damping")
REACH_LIMIT = 1e-5  # relative peak error above which a converged point counts as wrong


def _warm_seconds(call, repeats=3):
    call()  # compile
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(call().x_max)
        best = min(best, time.perf_counter() - start)
    return best


def _reference(fields, omegas, amplitudes):
    x, y = np.empty((amplitudes.size, omegas.size)), np.empty((amplitudes.size, omegas.size))
    stuck = np.empty((amplitudes.size, omegas.size))
    for i, amplitude in enumerate(amplitudes):
        for j, omega in enumerate(omegas):
            ref = coulomb_steady_state(**fields, omega=omega, amplitude=amplitude)
            if not ref["converged"]:
                raise SystemExit(f"the reference did not converge at {amplitude} N, {omega} rad/s")
            x[i, j], y[i, j], stuck[i, j] = ref["x_max"], ref["y_max"], ref["stick_fraction"]
    return x, y, stuck


def _errors(response, x, y, stuck):
    x_error = np.max(np.abs(np.asarray(response.x_max) / x - 1))
    moving = stuck < 1  # a terminal stuck throughout has no unique position
    y_error = np.max(np.abs(np.asarray(response.y_max)[moving] / y[moving] - 1))
    return x_error, y_error


def reach(n, seed):
    cases = family(n, seed)
    converged, wrong, worst, seconds = 0, 0, 0.0, 0.0
    for i, case in enumerate(cases):
        system = tj.TIDSystem(**{key: case[key] for key in SYSTEM_KEYS}, friction_width=0.0)
        start = time.perf_counter()
        response = tj.frequency_response(system, case["omega"], case["amplitude"])
        seconds += time.perf_counter() - start
        if not bool(response.converged):
            print(f"reach: case {i} did not converge", flush=True)
            continue
        converged += 1
        ref = coulomb_steady_state(**{key: case[key] for key in SYSTEM_KEYS},
                                   omega=case["omega"], amplitude=case["amplitude"])
        error = abs(float(response.x_max) / ref["x_max"] - 1)
        worst = max(worst, error)
        if error > REACH_LIMIT:
            wrong += 1
            print(f"reach: case {i} is {error:.1e} off the reference", flush=True)
    return dict(n=n, converged=converged, wrong=wrong, worst=worst, seconds=seconds)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", help="markdown file whose coulomb block is replaced")
    parser.add_argument("--reach", type=int, default=200, help="random structures (0: none)")
    args = parser.parse_args()

    smooth = tj.paper_system(friction_width=None)
    exact = smooth.replace(friction_width=0.0)
    omegas = np.asarray(tj.default_omegas(smooth, 61))
    amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
    fields = {key: float(getattr(smooth, key)) for key in SYSTEM_KEYS}
    start = time.perf_counter()
    x, y, stuck = _reference(fields, omegas, amplitudes)
    reference_s = time.perf_counter() - start
    print(f"reference: {reference_s:.0f} s", flush=True)

    rows = []
    for name, system in (("smoothed, relative width (0.02 omega A/K)", smooth),
                         ("exact Coulomb friction (`friction_width=0`)", exact)):
        call = lambda system=system: tj.frequency_response(system, omegas, amplitudes)
        seconds = _warm_seconds(call)
        response = call()
        converged = int(np.sum(np.asarray(response.converged)))
        x_error, y_error = _errors(response, x, y, stuck)
        rows.append((name, seconds / x.size, converged, x_error, y_error))

    lines = [
        f"{os.cpu_count()} CPU cores, JAX "
        f"{jax.__version__}, float64. Paper system, {amplitudes.size} amplitudes x "
        f"{omegas.size} frequencies, warm `frequency_response` (one call, best of 3); "
        f"errors against the event-driven reference ({reference_s:.0f} s for the surface).",
        "",
        "| friction | time per orbit | vs smoothed | converged | max error x_max | "
        "max error y_max |",
        "|---|---|---|---|---|---|",
    ]
    for name, per_orbit, converged, x_error, y_error in rows:
        lines.append(f"| {name} | {per_orbit * 1e3:.2f} ms | {rows[0][1] / per_orbit:.2f}x | "
                     f"{converged}/{x.size} | {x_error:.1e} | {y_error:.1e} |")
    if args.reach:
        reached = reach(args.reach, 0)
        lines += ["", f"Reach, exact friction: {reached['converged']}/{reached['n']} random "
                  f"structures of `tests/reference/family.py` converged "
                  f"({reached['seconds']:.0f} s in all, one call each); {reached['wrong']} "
                  f"more than {REACH_LIMIT:g} off the reference (largest error "
                  f"{reached['worst']:.1e})."]
    print("\n".join(lines))
    if args.readme:
        replace_block(args.readme, "coulomb", lines)


if __name__ == "__main__":
    main()
