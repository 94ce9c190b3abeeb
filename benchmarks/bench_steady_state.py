"""Steady-state speed and reach of tid_jax against the baselines a user would write, side by
side in one run, every method's peaks judged against the same long-run reference.

Run: `python benchmarks/bench_steady_state.py [--readme benchmarks/README.md]`. Prints
markdown tables (and, with `--readme`, replaces the tables in that file):

- the paper's system (friction width 1e-4 m/s) on its 61-frequency x 12-amplitude
  surface; the reference is a compiled Dormand-Prince transient over 300 periods at rtol
  1e-11 (`baselines.reference_peaks`);
- scipy LSODA as one `solve_ivp` call per point over the smallest number of periods that
  matches the reference within 1e-4 on 16 points spread over the surface (no restarts,
  samples only in the last period); a numba-compiled serial Dormand-Prince over the same
  periods; a naive vmapped diffrax transient over the same periods (all 732 points); and
  `tid_jax.frequency_response` (all 732 points in one call), with its default settings
  and looser integration tolerances (a row of its own for the fastest whose peaks all
  match the reference within 1e-4 on all 732 points, where that beats the default);
- time per orbit against batch size;
- the 12-amplitude paper retune in a child process (cold, then warm) on its defaults (one
  process per CPU core) and, side by side, in one process and with exact friction; and
  `tid-jax retune`, `tid-jax sensitivity` and `tid-jax robust` end to end on the paper's defaults,
  cold, again with the compilation cache filled by the first run, and then for two other
  amplitudes (`--cli-only`: this table alone, written to its own block of `--readme`);
- reach: random structures (`tests/reference/family.py`) at a friction width of 1e-4 m/s,
  each against the independent transient reference of `tests/reference/transient.py`.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import tid_jax as tj  # noqa: E402
from benchmarks import baselines  # noqa: E402
from tid_jax._peaks import DEFAULT_FREQUENCIES  # noqa: E402

WIDTH = 1e-4  # m/s, the friction width of every method here
MATCH = 1e-4  # peaks within this of the reference count as matched
REACH_LIMIT = 1e-3  # a converged point further than this from the reference is wrong
TIME_LIMIT_S = 900
BATCH_SIZES = (1, 10, 100, 1000)
# Looser integration tolerances tried for tid_jax at matched accuracy; the periodicity
# tolerance follows (10 rtol, no tighter than the default).
MATCHED_RTOLS = (1e-7, 1e-6, 1e-5)
SYSTEM_KEYS = ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
               "tid_stiffness", "tid_damping")


def timed(function):
    start = time.perf_counter()
    out = function()
    jax.block_until_ready(out)
    return out, time.perf_counter() - start


def warm_time(function, budget_s=2.0):
    """Mean wall time of `function()` (already compiled), repeated for about `budget_s`."""
    runs, start = 0, time.perf_counter()
    while runs == 0 or time.perf_counter() - start < budget_s:
        jax.block_until_ready(function())
        runs += 1
    return (time.perf_counter() - start) / runs


def max_error(values, reference):
    values, reference = np.asarray(values, float), np.asarray(reference, float)
    error = np.abs(values - reference) / np.abs(reference)
    return float(np.max(np.where(np.isfinite(error), error, np.inf)))


def choose_tid_settings(system, omegas, amplitudes, reference, default_seconds):
    """The fastest of the default settings (`default_seconds` per orbit) and looser
    tolerances `MATCHED_RTOLS` whose peaks on the whole surface all converge and match
    `reference` within `MATCH`: `(settings, per-orbit seconds, max error, tried)`, with
    `settings` None where the default is fastest."""
    tried, best = [], (None, default_seconds, None)
    for rtol in MATCHED_RTOLS:
        settings = tj.SolverSettings(rtol=rtol, atol=rtol,
                                     periodicity_tol=max(10 * rtol, 1e-6))
        call = lambda settings=settings: tj.frequency_response(system, omegas, amplitudes,
                                                              settings=settings)
        response, _ = timed(call)
        error = max_error(np.asarray(response.x_max).ravel(), reference)
        seconds = warm_time(call, budget_s=0) / reference.size
        tried.append((rtol, error, seconds))
        if error <= MATCH and bool(np.all(response.converged)) and seconds < best[1]:
            best = (settings, seconds, error)
    return (*best, tried)


# The paper retune's variants, side by side: (label, friction_width argument of
# `paper_system`, processes); the first is the defaults.
RETUNE_VARIANTS = (
    ("defaults (exact friction), `ProcessMap` of one process per CPU core", "", None),
    ("defaults, this process alone", "", 1),
    ("relative friction width (`friction_width=None`), `ProcessMap` of one process per "
     "CPU core", "friction_width=None", None),
)


def run_retune_child(limit_s, system_arguments="", workers=None):
    """The 12-amplitude paper retune on 61 frequencies in a child process (the system
    `paper_system(system_arguments)`, its amplitudes mapped over a `ProcessMap` of
    `workers` processes, default one per core; 1: this process alone): cold (import and
    compilation included, no compilation cache), then warm. Returns the wall
    times and the number of amplitudes with status ok, or None if stopped at `limit_s`."""
    code = f"""
import json, os, time
start = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import tid_jax as tj
system = tj.paper_system({system_arguments})
omegas = tj.default_omegas(system, {DEFAULT_FREQUENCIES})
processes = {workers if workers is not None else len(os.sched_getaffinity(0))}
pool = tj.ProcessMap(processes) if processes > 1 else (lambda f, tasks: [f(*t) for t in tasks])
run = lambda: jax.block_until_ready(tj.retune(system, tj.PAPER_AMPLITUDES, omegas=omegas,
                                              map_lanes=pool))
result = run()
cold = time.perf_counter() - start
again = time.perf_counter()
run()
print(json.dumps(dict(cold=cold, warm=time.perf_counter() - again,
                      ok=int(result.converged.sum()))))
"""
    env = dict(os.environ)
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=limit_s, env=env)
    except subprocess.TimeoutExpired:
        return None
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def retune_rows(limit_s) -> list[str]:
    """The paper retune's timings (`run_retune_child`) for each of `RETUNE_VARIANTS`, run
    one after the other: table rows."""
    rows = [f"| paper retune (`tj.retune`, 12 amplitudes x {DEFAULT_FREQUENCIES} frequencies, "
            "child process) | cold (import and compilation) | warm (same process) | "
            "status ok |", "|---|---|---|---|"]
    for label, arguments, workers in RETUNE_VARIANTS:
        retune = run_retune_child(limit_s, arguments, workers)
        text = (["stopped"] * 3 if retune is None else
                [f"{retune['cold']:.0f} s", f"{retune['warm']:.1f} s", f"{retune['ok']}/12"])
        rows.append(f"| {label} | " + " | ".join(text) + " |")
    return rows


# (command, flags): each on the paper's defaults, and the retune side by side in one
# process.
CLI_COMMANDS = (("retune", ()), ("retune", ("--workers", "1")), ("sensitivity", ()),
                ("robust", ()))


# The amplitudes of the third run of each command: others than the defaults, fewer of them.
OTHER_AMPLITUDES = ("250", "450")


def run_cli(command, cache_dir, limit_s, extra=()):
    """Wall time of `tid-jax COMMAND` on the paper's defaults (with the flags `extra`), end
    to end, in a child process (the console script's entry point, as a user runs it),
    with the compilation cache in `cache_dir`; None if stopped at `limit_s`."""
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        try:
            done = subprocess.run(
                [sys.executable, "-c", "from tid_jax.cli import run; run()", command,
                 "--out", folder, "--quiet", "--cache-dir", cache_dir, *extra],
                capture_output=True, text=True, timeout=limit_s,
            )
        except subprocess.TimeoutExpired:
            return None
        if done.returncode != 0:
            raise RuntimeError(done.stderr[-3000:])
        return time.perf_counter() - start


def cli_table(limit_s) -> list[str]:
    """`tid-jax retune`, `sensitivity` and `robust` on the paper's defaults, each with an
    empty compilation cache, again with the cache its first run filled, and then with
    `OTHER_AMPLITUDES` (the same cache): table rows."""
    other = " ".join(OTHER_AMPLITUDES)
    rows = ["| command (paper defaults, end to end) | first run, empty cache | "
            f"second run, cache filled | third run, `--amplitudes {other}` |",
            "|---|---|---|---|"]
    for command, flags in CLI_COMMANDS:
        with tempfile.TemporaryDirectory() as cache:
            walls = [run_cli(command, cache, limit_s, flags),
                     run_cli(command, cache, limit_s, flags),
                     run_cli(command, cache, limit_s,
                             (*flags, "--amplitudes", *OTHER_AMPLITUDES))]
        text = ["stopped" if wall is None else f"{wall:.0f} s" for wall in walls]
        rows.append(f"| `tid-jax {' '.join((command, *flags))}` | " + " | ".join(text) + " |")
    return rows


def reach(n, seed):
    """Random structures at the friction width `WIDTH`: tid_jax against the transient
    reference. Returns counts and the largest error among converged points."""
    from tests.reference.family import family
    from tests.reference.transient import transient_peaks

    cases = family(n, seed)
    converged, wrong, compared, worst, seconds = 0, 0, 0, 0.0, 0.0
    for i, case in enumerate(cases):
        system = tj.TIDSystem(**{key: case[key] for key in SYSTEM_KEYS}, friction_width=WIDTH)
        response, elapsed = timed(
            lambda system=system, case=case: tj.frequency_response(
                system, case["omega"], case["amplitude"]))
        seconds += elapsed
        if not bool(response.converged):
            print(f"reach: case {i} did not converge", flush=True)
            continue
        converged += 1
        reference = transient_peaks(case, WIDTH)
        if not reference["converged"]:
            print(f"reach: the reference did not converge for case {i}", flush=True)
            continue
        compared += 1
        error = abs(float(response.x_max) - reference["x_max"]) / reference["x_max"]
        worst = max(worst, error)
        wrong += error > REACH_LIMIT
    return dict(n=n, converged=converged, compared=compared, wrong=wrong, worst=worst,
                seconds=seconds)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", help="markdown file whose benchmark tables are replaced")
    parser.add_argument("--skip-retune", action="store_true")
    parser.add_argument("--reach", type=int, default=200, help="random structures (0: none)")
    parser.add_argument("--cli-only", action="store_true",
                        help="only the command-line table (its own block in --readme)")
    args = parser.parse_args()
    if args.cli_only:
        lines = [f"{os.cpu_count()} CPU cores, JAX "
                 f"{jax.__version__}.", "", *retune_rows(TIME_LIMIT_S), ""]
        lines += cli_table(TIME_LIMIT_S)
        print("\n".join(lines))
        if args.readme:
            replace_block(args.readme, "cli-table", lines)
        return

    system = tj.paper_system(friction_width=WIDTH)
    plain = dict(system.to_dict())
    surface_omegas = np.asarray(tj.default_omegas(system, 61))
    amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
    grid_omegas, grid_amplitudes = (a.ravel() for a in np.meshgrid(surface_omegas, amplitudes))
    orbits = grid_omegas.size
    spread = np.ravel_multi_index(np.meshgrid([0, 4, 8, 11], [6, 24, 36, 54], indexing="ij"),
                                  (amplitudes.size, surface_omegas.size)).ravel()
    lines = []

    def say(line=""):
        print(line, flush=True)
        lines.append(line)

    baselines.warmup()
    (reference_x, _), reference_s = timed(
        lambda: baselines.reference_peaks(plain, grid_omegas, grid_amplitudes, periods=300))
    print(f"reference: {reference_s:.0f} s", flush=True)

    chosen = baselines.choose_lsoda_periods(plain, grid_omegas[spread],
                                            grid_amplitudes[spread], reference_x[spread],
                                            tol=MATCH)
    periods = chosen["periods"]
    lsoda_per_orbit = chosen["seconds"] / spread.size
    lsoda_error = chosen["max_rel_err"]

    (numba_x, _), numba_s = timed(lambda: baselines.numba_dopri5_peaks(
        plain, grid_omegas[spread], grid_amplitudes[spread], periods=periods))
    numba_error = max_error(numba_x, reference_x[spread])

    naive = lambda: baselines.naive_diffrax_peaks(plain, grid_omegas, grid_amplitudes,
                                                  periods=periods)
    (naive_x, _), naive_cold = timed(naive)
    (naive_x, _), naive_s = timed(naive)
    naive_error = max_error(naive_x, reference_x)

    surface = lambda: tj.frequency_response(system, surface_omegas, amplitudes)
    response, surface_cold = timed(surface)
    surface_warm = warm_time(surface, budget_s=0)
    tid_error = max_error(np.asarray(response.x_max).ravel(), reference_x)
    tid_converged = int(np.sum(np.asarray(response.converged)))
    tid_per_orbit = surface_warm / orbits
    matched, matched_per_orbit, matched_error, matched_tried = choose_tid_settings(
        system, surface_omegas, amplitudes, reference_x, tid_per_orbit)

    scaling = []
    band = (surface_omegas[0], surface_omegas[-1])
    for size in BATCH_SIZES:
        n_amp = {1: 1, 10: 1, 100: 10, 1000: 10}[size]
        omegas = np.linspace(*band, size // n_amp)
        amps = np.geomspace(amplitudes[0], amplitudes[-1], n_amp)
        call = lambda omegas=omegas, amps=amps: tj.frequency_response(system, omegas, amps).x_max
        _, cold = timed(call)
        scaling.append((size, cold, warm_time(call, budget_s=2.0 if size < 1000 else 0)))

    retune = cli_rows = None
    if not args.skip_retune:
        retune = retune_rows(TIME_LIMIT_S)
        cli_rows = cli_table(TIME_LIMIT_S)
    reached = reach(args.reach, 0) if args.reach else None

    say(f"Machine: {platform.processor() or 'x86_64'}"
        f" CPU, {os.cpu_count()} cores, {len(jax.devices())} JAX device(s); JAX "
        f"{jax.__version__}, float64. Paper system, friction width {WIDTH:g} m/s, "
        f"{amplitudes.size} amplitudes x {surface_omegas.size} frequencies; reference: 300 "
        f"periods at rtol 1e-11 ({reference_s:.0f} s).")
    say()
    say("| method | periods | points | time per orbit | vs LSODA | max peak error |")
    say("|---|---|---|---|---|---|")
    say(f"| scipy LSODA, rtol 1e-6, one `solve_ivp` call per point | {periods} | "
        f"{spread.size} | {lsoda_per_orbit * 1e3:.1f} ms | 1x | {lsoda_error:.1e} |")
    say(f"| numba-compiled serial Dormand-Prince, rtol 1e-8 | {periods} | {spread.size} | "
        f"{numba_s / spread.size * 1e3:.2f} ms | {lsoda_per_orbit / (numba_s / spread.size):.0f}x"
        f" | {numba_error:.1e} |")
    say(f"| naive vmapped diffrax Tsit5, rtol 1e-8 | {periods} | {orbits} | "
        f"{naive_s / orbits * 1e3:.2f} ms | {lsoda_per_orbit / (naive_s / orbits):.0f}x | "
        f"{naive_error:.1e} |")
    say(f"| tid_jax `frequency_response`, default settings (rtol "
        f"{tj.SolverSettings().rtol:g}; {tid_converged}/{orbits} converged) | - | "
        f"{orbits} | {tid_per_orbit * 1e3:.2f} ms | {lsoda_per_orbit / tid_per_orbit:.0f}x | "
        f"{tid_error:.1e} |")
    if matched is not None:
        say(f"| tid_jax `frequency_response`, tolerances matched to {MATCH:g} (rtol "
            f"{matched.rtol:g}) | - | {orbits} | {matched_per_orbit * 1e3:.2f} ms | "
            f"{lsoda_per_orbit / matched_per_orbit:.0f}x | {matched_error:.1e} |")
    say()
    say(f"tid_jax with looser tolerances (a row above if faster than the default within "
        f"{MATCH:g}, all converged): "
        + ", ".join(f"rtol {r:g}: {e:.1e}, {t * 1e3:.2f} ms" for r, e, t in matched_tried) + ".")
    say()
    say(f"Compilation (first call minus warm call): tid_jax {surface_cold - surface_warm:.1f} s,"
        f" naive diffrax {naive_cold - naive_s:.1f} s. LSODA tried "
        + ", ".join(f"{n} periods: {e:.1e}" for n, e, _ in chosen["tried"]) + ".")
    say()
    say("| batch size (orbits) | first call (compile + run) | warm call | warm time per orbit |")
    say("|---|---|---|---|")
    for size, cold, warm in scaling:
        say(f"| {size} | {cold:.2f} s | {warm:.3f} s | {warm / size * 1e3:.2f} ms |")
    if not args.skip_retune:
        say()
        for row in retune:
            say(row)
        say()
        for row in cli_rows:
            say(row)
    if reached is not None:
        say()
        say(f"Reach: {reached['converged']}/{reached['n']} random structures converged "
            f"(friction width {WIDTH:g} m/s; tid_jax {reached['seconds']:.0f} s in all, one call "
            f"each); {reached['wrong']} of the {reached['compared']} compared with the "
            f"transient reference are more than {REACH_LIMIT:g} off (largest error "
            f"{reached['worst']:.1e}).")

    if args.readme:
        replace_block(args.readme, "table", lines)


def replace_block(path, name, lines):
    """Replace the lines between `<!-- NAME:begin -->` and `<!-- NAME:end -->` in `path`."""
    with open(path) as f:
        text = f.read()
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    if begin not in text or end not in text:
        raise SystemExit(f"{path} has no {begin} ... {end} block")
    head, _, rest = text.partition(begin)
    _, _, tail = rest.partition(end)
    with open(path, "w") as f:
        f.write(head + begin + "\n" + "\n".join(lines) + "\n" + end + tail)


if __name__ == "__main__":
    main()
