"""Sensitivity study beyond the paper: elasticities d ln(peak) / d ln(p) of the peak host
displacement and of the peak inerter stroke with respect to every physical parameter and
the forcing amplitude, against forcing amplitude, at Den Hartog's tuning and at the tuning
retuned for each amplitude (envelope theorem and implicit differentiation, no re-runs; the
optimum of every amplitude from one batched `best_tunings`).

Writes sensitivity_vs_amplitude.csv and .png to --out (default docs/figures/)."""

import argparse
import os
import time
from pathlib import Path

import jax
import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    parser.add_argument("--n-frequencies", type=int, default=61, help="frequencies in the band")
    parser.add_argument("--amplitudes", type=float, nargs="+", help="N (default: the paper's)")
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    # equinox's run-time checks as NaN (read when the library imports equinox): programs
    # holding them are then kept in the compilation cache; every solve reports its status
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import tid_jax as tj

    tj.enable_compilation_cache()  # $TID_JAX_CACHE_DIR=off turns it off
    from tid_jax import plot
    from tid_jax._optimise._design import PARAMETER_UNITS
    from tid_jax._runtime._io import write_csv
    from tid_jax._sensitivity import elasticity_series

    system = tj.paper_system(friction_width=None)  # the relative width of docs/figures
    amplitudes = np.asarray(args.amplitudes or tj.PAPER_AMPLITUDES, dtype=float)
    omegas = tj.default_omegas(system, args.n_frequencies)
    k_dh, c_dh = float(system.tid_stiffness), float(system.tid_damping)
    stiffness = float(system.host_stiffness)
    start = time.perf_counter()
    # The optimum at every amplitude, all in one batch.
    best = tj.best_tunings(system, amplitudes, omegas=omegas)
    results = tj.amplitude_sensitivities(system, amplitudes, omegas=omegas, best=best)
    for amplitude, result in zip(amplitudes, results, strict=True):
        optimum = result.optimum
        print(
            f"A = {amplitude:6g} N: x/(A/K) {float(result.host_peak) * stiffness / amplitude:.3f}; "
            f"optimum k/k_DH {float(optimum.tid_stiffness) / k_dh:.4f}, "
            f"c/c_DH {float(optimum.tid_damping) / c_dh:.4f}, "
            f"{'converged' if bool(optimum.converged) else 'NOT converged'} "
            f"({time.perf_counter() - start:.0f} s)",
            flush=True,
        )

    parameters = results[0].parameters
    header = [
        "amplitude_N",
        "parameter",
        "value",
        "unit",
        "host_peak_m",
        "host_elasticity",
        "stroke_peak_m",
        "stroke_elasticity",
        "optimum_k_over_k_den_hartog",
        "optimum_c_over_c_den_hartog",
        "optimum_host_peak_m",
        "optimum_host_elasticity",
        "optimum_stroke_peak_m",
        "optimum_stroke_elasticity",
        "optimum_stiffness_elasticity",
        "optimum_damping_elasticity",
        "optimum_damping_at_bound",
        "steady_states_converged",
        "optimum_converged",
    ]
    rows = []
    for amplitude, result in zip(amplitudes, results, strict=True):
        optimum = result.optimum
        for i, name in enumerate(parameters):
            rows.append([
                amplitude,
                name,
                float(result.values[i]),
                PARAMETER_UNITS[name],
                float(result.host_peak),
                float(result.host_elasticity[i]),
                float(result.stroke_peak),
                float(result.stroke_elasticity[i]),
                float(optimum.tid_stiffness) / k_dh,
                float(optimum.tid_damping) / c_dh,
                float(optimum.host_peak),
                float(optimum.host_elasticity[i]),
                float(optimum.stroke_peak),
                float(optimum.stroke_elasticity[i]),
                float(optimum.stiffness_elasticity[i]),
                # Undefined where c* is held at 0 by its bound: left empty.
                "" if bool(optimum.damping_at_bound) else float(optimum.damping_elasticity[i]),
                bool(optimum.damping_at_bound),
                bool(result.converged),
                bool(optimum.converged),
            ])
    write_csv(args.out / "sensitivity_vs_amplitude.csv", header, rows)

    host, stroke, optimum_host, optimum_stroke = elasticity_series(results)
    plot.save_figure(
        plot.plot_elasticities(
            amplitudes, host, stroke, optimum_host=optimum_host, optimum_stroke=optimum_stroke,
            title="Elasticities of the peak responses, paper's system: Den Hartog tuning "
            "(solid) and retuned for each amplitude (dashed)",
        ),
        args.out / "sensitivity_vs_amplitude.png",
    )
    print(f"wrote {args.out}/sensitivity_vs_amplitude.{{csv,png}} "
          f"in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
