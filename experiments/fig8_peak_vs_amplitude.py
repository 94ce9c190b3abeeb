"""Figure 8 of the paper: peak host displacement (over A/K) and peak inerter stroke against
forcing amplitude for four designs: the linear (frictionless) TID and the dry-friction TID
tuned by Den Hartog, retuned for each amplitude, and retuned for A = 200 N only.

Writes fig8_peak_vs_amplitude.csv and .png to --out (default docs/figures/). With
--retuned FILE, the per-amplitude tuning is read from the CSV written by fig6_7_retuning.py
(columns amplitude_N, k_N_per_m, c_N_s_per_m) instead of being retuned again."""

import argparse
import csv
import os
from pathlib import Path

import jax
import numpy as np

RETUNED_FOR = 200.0  # N, the paper's "retuned for A = 200 N only"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    parser.add_argument(
        "--retuned",
        type=Path,
        metavar="FILE",
        help="fig7_retuned_parameters.csv to take the retuned k and c from",
    )
    parser.add_argument(
        "--n-frequencies", type=int, default=121, help="frequencies over which each peak is taken"
    )
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    # equinox's run-time checks as NaN (read when the library imports equinox): programs
    # holding them are then kept in the compilation cache; every solve reports its status
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import tid_jax as tj

    tj.enable_compilation_cache()  # $TID_JAX_CACHE_DIR=off turns it off
    from tid_jax import plot
    from tid_jax._runtime._io import write_csv

    system = tj.paper_system(friction_width=None)  # the relative width of docs/figures
    amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
    static = amplitudes / float(system.host_stiffness)

    omegas = tj.default_omegas(system, args.n_frequencies)
    fine = np.linspace(float(omegas[0]), float(omegas[-1]), 4001)
    linear = tj.linear_receptance(system, fine)
    linear_x = np.full(amplitudes.shape, np.max(np.abs(linear.host)) * float(system.host_stiffness))
    linear_y = np.max(np.abs(linear.inerter)) * amplitudes

    if args.retuned is None:
        result = tj.retune(system, amplitudes, progress=print)
        tuning = dict(
            zip(
                amplitudes,
                zip(np.asarray(result.tid_stiffness), np.asarray(result.tid_damping), strict=True),
                strict=True,
            )
        )
    else:
        with open(args.retuned, newline="") as file:
            tuning = {
                float(row["amplitude_N"]): (float(row["k_N_per_m"]), float(row["c_N_s_per_m"]))
                for row in csv.DictReader(file)
            }

    def tuned_for(a):
        k, c = tuning[a]
        return system.replace(tid_stiffness=k, tid_damping=c)

    den_hartog = tj.peaks(system, omegas, amplitudes)
    each = [tj.peaks(tuned_for(a), omegas, a) for a in amplitudes]
    retuned_x = np.array([float(p.x_peak[0]) for p in each])
    retuned_y = np.array([float(p.y_peak[0]) for p in each])
    fixed = tj.peaks(tuned_for(RETUNED_FOR), omegas, amplitudes)
    designs = (
        (
            "linear TID (no friction), Den Hartog",
            linear_x,
            linear_y,
            dict(color="black", linestyle="-.", marker="."),
        ),
        (
            "friction TID, Den Hartog",
            np.asarray(den_hartog.x_peak) / static,
            np.asarray(den_hartog.y_peak),
            dict(color="tab:red", linestyle="--", marker="."),
        ),
        (
            "friction TID, retuned for each A",
            retuned_x / static,
            retuned_y,
            dict(color="tab:blue", linewidth=2.0, marker="."),
        ),
        (
            f"friction TID, retuned for A = {RETUNED_FOR:g} N only",
            np.asarray(fixed.x_peak) / static,
            np.asarray(fixed.y_peak),
            dict(color="tab:green", marker="o"),
        ),
    )
    write_csv(
        args.out / "fig8_peak_vs_amplitude.csv",
        [
            "amplitude_N",
            "x_linear_over_A_K",
            "y_linear_m",
            "x_den_hartog_over_A_K",
            "y_den_hartog_m",
            "x_retuned_over_A_K",
            "y_retuned_m",
            f"x_retuned_{RETUNED_FOR:g}N_over_A_K",
            f"y_retuned_{RETUNED_FOR:g}N_m",
        ],
        [
            [a, *(value for _, x, y, _ in designs for value in (x[n], y[n]))]
            for n, a in enumerate(amplitudes)
        ],
    )
    plot.save_figure(
        plot.plot_peaks_vs_amplitude(
            [(label, amplitudes, x, y, style) for label, x, y, style in designs],
            stroke_limit=tj.PAPER_STROKE,
            title="Peak responses against forcing amplitude (paper Figure 8)",
        ),
        args.out / "fig8_peak_vs_amplitude.png",
    )
    for n, a in enumerate(amplitudes):
        print(f"A = {a:6g} N: x/(A/K) " + ", ".join(f"{x[n]:.2f}" for _, x, _, _ in designs))
    print(f"wrote {args.out}/fig8_peak_vs_amplitude.{{csv,png}}")


if __name__ == "__main__":
    main()
