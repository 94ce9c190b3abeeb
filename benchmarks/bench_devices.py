"""The batched solves and the retune on one JAX device and on several, side by side in
one run (several CPU devices simulated with `--xla_force_host_platform_device_count`,
each count in a process of its own, since it is fixed when JAX starts).

Run: `python benchmarks/bench_devices.py [--devices 1 4] [--readme benchmarks/README.md]`.
Prints markdown (and, with `--readme`, replaces the `devices` block of that file): for
each device count, on the paper's system (exact friction, the default), the time of a
first and of a later `frequency_response` over the 61-frequency x 12-amplitude surface
(every point in one call; the first compiles), of a first and a later `retune` at 200 and
600 N on the default band, and the largest difference from the first count's peaks and
retuned tunings. One process (no `ProcessMap`) and no compilation cache.
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from benchmarks.bench_steady_state import replace_block  # noqa: E402

MEASURE = """
import json, time
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import tid_jax as tj

system = tj.paper_system()
omegas = np.asarray(tj.default_omegas(system, 61))
amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
out = dict(devices=len(jax.devices()))
for name, call, read in (
    ("frf", lambda: tj.frequency_response(system, omegas, amplitudes), lambda r: r.x_max),
    ("retune", lambda: tj.retune(system, [200.0, 600.0]), lambda r: r.tid_stiffness),
):
    times = []
    for _ in range(3):
        start = time.perf_counter()
        result = call()
        np.asarray(read(result))
        times.append(time.perf_counter() - start)
    out[name + "_first"], out[name + "_later"] = times[0], min(times[1:])
    out[name] = result
out["x_max"] = np.asarray(out.pop("frf").x_max).tolist()
retuned = out.pop("retune")
out["k"] = np.asarray(retuned.tid_stiffness).tolist()
out["c"] = np.asarray(retuned.tid_damping).tolist()
out["status"] = np.asarray(retuned.status).tolist()
print(json.dumps(out))
"""


def measure(devices: int) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu",
               XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    env.pop("TID_JAX_CACHE_DIR", None)
    done = subprocess.run([sys.executable, "-c", MEASURE], env=env, capture_output=True,
                          text=True, cwd=ROOT)
    if done.returncode:
        raise SystemExit(f"{devices} device(s) failed:\n{done.stderr[-4000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _largest_relative(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b) / np.abs(b)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, nargs="+", default=[1, 4],
                        help="device counts, the first the reference (default 1 4)")
    parser.add_argument("--readme", help="markdown file whose devices block is replaced")
    args = parser.parse_args()
    runs = []
    for count in args.devices:
        runs.append(measure(count))
        print(f"{count} device(s) done", flush=True)
    first = runs[0]
    lines = [
        f"{os.cpu_count()} CPU cores, CPU devices "
        f"simulated; paper system (exact friction), no worker processes, no compilation "
        f"cache. `frequency_response`: 61 frequencies x 12 amplitudes in one call; `retune`: "
        f"200 and 600 N on the default band. First call (compiling), then the best of two "
        f"later ones; differences against {first['devices']} device(s).",
        "",
        "| devices | frf first | frf later | retune first | retune later | frf vs first row | "
        "peaks: largest difference | k, c: largest difference | retune status |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for run in runs:
        lines.append(
            f"| {run['devices']} | {run['frf_first']:.1f} s | {run['frf_later']:.2f} s | "
            f"{run['retune_first']:.1f} s | {run['retune_later']:.1f} s | "
            f"{first['frf_later'] / run['frf_later']:.2f}x | "
            f"{_largest_relative(run['x_max'], first['x_max']):.1e} | "
            f"{max(_largest_relative(run[key], first[key]) for key in ('k', 'c')):.1e} | "
            f"{run['status']} |")
    print("\n".join(lines))
    if args.readme:
        replace_block(args.readme, "devices", lines)


if __name__ == "__main__":
    main()
