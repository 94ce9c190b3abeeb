"""Steady-state throughput of tid_jax against the scipy LSODA baseline, side by side.

Run: `python benchmarks/bench_steady_state.py [--readme benchmarks/README.md]`.
Prints a markdown table (and, with `--readme`, replaces the table in that file):

- baseline: `scipy.integrate.solve_ivp(method="LSODA")` on the same smoothed equations
  (eq. (12), tanh friction), from rest, one forcing period per call, until the peak |x| of
  a period changes by less than 1e-6 (relative) from the previous one;
- tid_jax (`frequency_response`, shooting, batched) on the same points; the peaks must
  agree within 0.1 %;
- the 61-frequency x 12-amplitude surface, compile time apart from run time;
- the 12-amplitude paper retune in a child process with a time limit: cold (import and
  compile included), then a second, warm call, both at the default tolerance, then warm
  at tolerance 1e-5 for comparison; and `tid-jax retune` on the paper's
  defaults, cold and end to end (import, compile, solve, plots, files);
- peak memory (ru_maxrss) and time per orbit against batch size.
"""

import argparse
import datetime
import inspect
import json
import platform
import resource
import subprocess
import sys
import tempfile
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import tid_jax as tj  # noqa: E402
from tid_jax._retune import DEFAULT_FREQUENCIES  # noqa: E402

DEFAULT_TOL = inspect.signature(tj.retune).parameters["tol"].default
TIGHT_TOL = 1e-5

RETUNE_TIME_LIMIT_S = 600
BATCH_SIZES = (1, 10, 100, 1000, 10000)


def peak_memory_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def lsoda_peak(system, omega, amplitude, *, rtol=1e-5, max_periods=300, samples=2000):
    """Peak |x| (m) of the steady state at one point, by time integration from rest."""
    mass, stiffness, damping = system.host_mass, system.host_stiffness, system.host_damping
    inertance, friction, width = system.inertance, system.friction_force, system.friction_width
    k, c = system.tid_stiffness, system.tid_damping

    def rhs(t, z):
        x, v, y, w = z
        spring = k * (x - y) + c * (v - w)
        return [
            v,
            (amplitude * np.sin(omega * t) - damping * v - stiffness * x - spring) / mass,
            w,
            (spring - friction * np.tanh(w / width)) / inertance,
        ]

    period = 2 * np.pi / omega
    static = amplitude / stiffness
    atol = rtol * 0.1 * static * np.array([1.0, omega, 1.0, omega])
    z, previous = np.zeros(4), np.inf
    for n in range(max_periods):
        t0 = n * period
        sol = solve_ivp(rhs, (t0, t0 + period), z, method="LSODA", rtol=rtol, atol=atol,
                        dense_output=True)
        peak = np.max(np.abs(sol.sol(np.linspace(t0, t0 + period, samples))[0]))
        z = sol.y[:, -1]
        if abs(peak - previous) < 1e-6 * peak:
            return peak, n + 1
        previous = peak
    return peak, max_periods


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


def run_retune_child(amplitudes, n_frequencies, tight_tol, limit_s):
    """The 12-amplitude retune in a child process (so that it can be stopped at `limit_s`):
    cold at the default tolerance (import and compile included), then warm, then warm at
    `tight_tol` for comparison. Returns the wall times of the cold run's stages and of each
    run, the largest relative difference of the peaks and designs between the two
    tolerances, and the child's wall time; None if stopped."""
    code = f"""
import json, time
start = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import tid_jax as tj
system = tj.paper_system()
stages = []
say = lambda message: stages.append((round(time.perf_counter() - start, 2), message))
run = lambda progress, **kwargs: jax.block_until_ready(tj.retune(
    system, {list(amplitudes)!r}, omegas=tj.default_omegas(system, {n_frequencies}),
    progress=progress, **kwargs))
result = run(say)
cold = time.perf_counter() - start
again = time.perf_counter()
run(None)
warm = time.perf_counter() - again
again = time.perf_counter()
tight = run(None, tol={tight_tol!r})
warm_tight = time.perf_counter() - again
difference = lambda name: float(np.max(np.abs(np.asarray(getattr(result, name))
                                              / np.asarray(getattr(tight, name)) - 1)))
print(json.dumps(dict(total=cold, warm=warm, warm_tight=warm_tight, stages=stages,
                      converged=int(result.converged.sum()),
                      converged_tight=int(tight.converged.sum()),
                      peak_difference=difference("x_peak"),
                      stiffness_difference=difference("tid_stiffness"))))
"""
    start = time.perf_counter()
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=limit_s)
    except subprocess.TimeoutExpired:
        return None, time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(done.stderr[-3000:])
    return json.loads(done.stdout.strip().splitlines()[-1]), time.perf_counter() - start


def run_cli_retune(limit_s):
    """Wall time of `tid-jax retune` on the paper's defaults, cold, in a child process
    writing to a temporary folder; None if stopped at `limit_s`."""
    with tempfile.TemporaryDirectory() as folder:
        start = time.perf_counter()
        try:
            done = subprocess.run(
                [sys.executable, "-m", "tid_jax.cli", "retune", "--out", folder, "--quiet"],
                capture_output=True, text=True, timeout=limit_s,
            )
        except subprocess.TimeoutExpired:
            return None
        if done.returncode != 0:
            raise RuntimeError(done.stderr[-3000:])
        return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readme", help="markdown file whose benchmark table is replaced")
    parser.add_argument("--skip-retune", action="store_true")
    args = parser.parse_args()

    system = tj.paper_system()
    surface_omegas = np.asarray(tj.default_omegas(system, 61))
    surface_amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
    lines = []

    def say(line=""):
        print(line, flush=True)
        lines.append(line)

    # 16 points spread over the surface: 4 amplitudes x 4 frequencies.
    omegas = surface_omegas[[6, 24, 36, 54]]
    amplitudes = surface_amplitudes[[0, 4, 8, 11]]

    start = time.perf_counter()
    baseline = np.empty((amplitudes.size, omegas.size))
    periods = np.empty_like(baseline, dtype=int)
    for i, amplitude in enumerate(amplitudes):
        for j, omega in enumerate(omegas):
            baseline[i, j], periods[i, j] = lsoda_peak(system, omega, amplitude)
    scipy_per_orbit = (time.perf_counter() - start) / baseline.size

    points = lambda: tj.frequency_response(system, omegas, amplitudes).x_max
    x_points, points_cold = timed(points)
    points_warm = warm_time(points)
    agreement = np.max(np.abs(np.asarray(x_points) - baseline) / baseline)

    surface = lambda: tj.frequency_response(system, surface_omegas, surface_amplitudes)
    response, surface_cold = timed(surface)
    surface_warm = warm_time(surface, budget_s=0)
    surface_orbits = surface_omegas.size * surface_amplitudes.size
    surface_converged = int(np.sum(np.asarray(response.converged)))
    surface_per_orbit = surface_warm / surface_orbits

    scaling = []
    band = (surface_omegas[0], surface_omegas[-1])
    for size in BATCH_SIZES:
        n_amp = {1: 1, 10: 1, 100: 10, 1000: 10, 10000: 100}[size]
        grid_omegas = np.linspace(*band, size // n_amp)
        grid_amplitudes = np.geomspace(surface_amplitudes[0], surface_amplitudes[-1], n_amp)
        call = lambda: tj.frequency_response(system, grid_omegas, grid_amplitudes).x_max
        _, cold = timed(call)
        warm = warm_time(call, budget_s=2.0 if size < 1000 else 0)
        scaling.append((size, cold, warm))
        print(f"batch {size}: cold {cold:.2f} s, warm {warm:.3f} s", flush=True)
    memory_after_batches = peak_memory_mb()

    retune_amplitudes = tj.PAPER_AMPLITUDES
    if args.skip_retune:
        retune, retune_wall, cli_wall = None, float("nan"), None
    else:
        retune, retune_wall = run_retune_child(
            retune_amplitudes, DEFAULT_FREQUENCIES, TIGHT_TOL, RETUNE_TIME_LIMIT_S
        )
        cli_wall = run_cli_retune(RETUNE_TIME_LIMIT_S)

    ratio_points = scipy_per_orbit / (points_warm / baseline.size)
    ratio_surface = scipy_per_orbit / surface_per_orbit
    say(f"Date: {datetime.date.today().isoformat()}; machine: {platform.processor() or 'x86_64'}"
        f" CPU, {len(jax.devices())} JAX device(s), 2 cores; "
        f"JAX {jax.__version__}, float64.")
    say()
    say("| quantity | scipy LSODA | tid_jax | ratio |")
    say("|---|---|---|---|")
    say(f"| per orbit, 16 points spread over the surface (tid_jax as one batch of 16) | "
        f"{scipy_per_orbit * 1e3:.1f} ms | {points_warm / baseline.size * 1e3:.2f} ms | "
        f"{ratio_points:.0f}x |")
    say(f"| per orbit, throughput on the 61 x 12 surface (batch of {surface_orbits}) | "
        f"{scipy_per_orbit * 1e3:.1f} ms | {surface_per_orbit * 1e3:.2f} ms | "
        f"{ratio_surface:.0f}x |")
    say(f"| matched accuracy: max relative difference of peak x on the 16 points | - | "
        f"{agreement:.1e} | (limit 1e-3) |")
    say(f"| LSODA periods to steady state (median / max) | {int(np.median(periods))} / "
        f"{int(periods.max())} | shooting, 2 transient periods | |")
    say(f"| 61 x 12 surface: run (warm) | {surface_orbits * scipy_per_orbit:.0f} s "
        f"(estimated) | {surface_warm:.2f} s ({surface_converged}/{surface_orbits} converged) | "
        f"{surface_orbits * scipy_per_orbit / surface_warm:.0f}x |")
    say(f"| 61 x 12 surface: compile (first call minus warm call) | - | "
        f"{surface_cold - surface_warm:.2f} s | |")
    if retune is None and not args.skip_retune:
        retune_text = f"not finished after {retune_wall:.0f} s (stopped)"
    elif retune is None:
        retune_text = "not run"
    else:
        first = next((t for t, message in retune["stages"] if "stage 1" in message),
                     float("nan"))
        retune_text = (f"{retune['total']:.0f} s cold incl. compile and import (first stage "
                       f"done at {first:.0f} s); {retune['warm']:.1f} s warm (second call); "
                       f"{retune['converged']}/{len(retune_amplitudes)} status ok")
    say(f"| paper retune, {len(retune_amplitudes)} amplitudes, 61 frequencies, default tol "
        f"{DEFAULT_TOL:g} | - | {retune_text} | |")
    if retune is not None:
        say(f"| the same at tol {TIGHT_TOL:g} (warm) | - | {retune['warm_tight']:.1f} s; "
            f"{retune['converged_tight']}/{len(retune_amplitudes)} status ok; peaks within "
            f"{retune['peak_difference']:.1e} and k within {retune['stiffness_difference']:.1e} "
            f"of the default's | |")
    if not args.skip_retune:
        cli_text = (f"{cli_wall:.0f} s" if cli_wall is not None
                    else f"not finished after {RETUNE_TIME_LIMIT_S} s (stopped)")
        say(f"| `tid-jax retune` (paper defaults), cold, end to end incl. import, plots and "
            f"files | - | {cli_text} | |")
    say(f"| peak memory (ru_maxrss, benchmark process, after all batches) | - | "
        f"{memory_after_batches:.0f} MB | |")
    say()
    say("| batch size (orbits) | first call (compile + run) | warm call | warm time per orbit |")
    say("|---|---|---|---|")
    for size, cold, warm in scaling:
        say(f"| {size} | {cold:.2f} s | {warm:.3f} s | {warm / size * 1e3:.2f} ms |")
    if retune is not None:
        say()
        say("Retune stages (seconds since the child process started): " + "; ".join(
            f"{t:.0f} s: {message}" for t, message in retune["stages"]))

    if args.readme:
        with open(args.readme) as f:
            text = f.read()
        begin, end = "<!-- table:begin -->", "<!-- table:end -->"
        head, _, rest = text.partition(begin)
        _, _, tail = rest.partition(end)
        with open(args.readme, "w") as f:
            f.write(head + begin + "\n" + "\n".join(lines) + "\n" + end + tail)


if __name__ == "__main__":
    main()
