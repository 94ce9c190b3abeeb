"""Exact Coulomb friction (`friction_width=0`) beside the smoothed model on the paper's
system.

1. The twelve amplitudes retuned on both models: k, c and the peak host displacement,
   with their differences (exact_friction_retune.csv).
2. The paper's designs at 200, 400 and 600 N (section 4.2) judged on both models
   (exact_friction_paper_designs.csv).
3. The smoothed model's peak error against exact friction as the width shrinks, at a
   stick-slip and at a sliding point (friction_width_error.csv/.png).

Writes to --out (default docs/figures/) and prints the tables."""

import argparse
import math
import os
from pathlib import Path

import jax
import numpy as np

PAPER_DESIGNS = ((200.0, 1.09, 0.45), (400.0, 1.034, 0.85), (600.0, 1.018, 0.90))
# (amplitude N, frequency / host frequency): a stick-slip point and a sliding one
WIDTH_POINTS = ((100.0, 1.1), (200.0, 0.85), (600.0, 1.0))
WIDTHS = np.logspace(-2, -6, 9)  # m/s


def _table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + " ---: |" * len(header)]
    lines += ["| " + " | ".join(rows_i) + " |" for rows_i in rows]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # equinox's run-time checks as NaN (read when the library imports equinox): programs
    # holding them are then kept in the compilation cache; every solve reports its status
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import tid_jax as tj

    tj.enable_compilation_cache()  # $TID_JAX_CACHE_DIR=off turns it off
    from tid_jax import plot
    from tid_jax._runtime._io import write_csv

    smooth = tj.paper_system(friction_width=None)
    exact = smooth.replace(friction_width=0.0)
    k_dh, c_dh = float(smooth.tid_stiffness), float(smooth.tid_damping)
    amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
    static = amplitudes / float(smooth.host_stiffness)

    # 1. retuned on both models
    results = {name: tj.retune(system, amplitudes, progress=print)
               for name, system in (("smoothed", smooth), ("exact", exact))}
    rows = []
    for i, amplitude in enumerate(amplitudes):
        s, e = results["smoothed"], results["exact"]
        ks, ke = float(s.tid_stiffness[i]), float(e.tid_stiffness[i])
        cs, ce = float(s.tid_damping[i]), float(e.tid_damping[i])
        xs, xe = float(s.x_peak[i]) / static[i], float(e.x_peak[i]) / static[i]
        rows.append([amplitude, ks / k_dh, ke / k_dh, cs / c_dh, ce / c_dh, xs, xe,
                     xe / xs - 1, s.status_messages()[i], e.status_messages()[i]])
    write_csv(
        args.out / "exact_friction_retune.csv",
        ["amplitude_N", "k_over_k_DH_smoothed", "k_over_k_DH_exact", "c_over_c_DH_smoothed",
         "c_over_c_DH_exact", "x_peak_over_A_K_smoothed", "x_peak_over_A_K_exact",
         "x_peak_relative_difference", "status_smoothed", "status_exact"],
        rows,
    )
    print(_table(
        ["A [N]", "k/k_DH smoothed", "k/k_DH exact", "c/c_DH smoothed", "c/c_DH exact",
         "x/(A/K) smoothed", "x/(A/K) exact", "difference"],
        [[f"{r[0]:g}", f"{r[1]:.4f}", f"{r[2]:.4f}", f"{r[3]:.3f}", f"{r[4]:.3f}",
          f"{r[5]:.4f}", f"{r[6]:.4f}", f"{100 * r[7]:+.3f}%"] for r in rows],
    ))

    # 2. the paper's designs judged on both models
    omegas = np.asarray(tj.default_omegas(smooth))
    design_rows = []
    for amplitude, k_ratio, c_ratio in PAPER_DESIGNS:
        tuned = {"smoothed": smooth, "exact": exact}
        peaks = {
            name: float(tj.peak_response(system.replace(tid_stiffness=k_ratio * k_dh,
                                                        tid_damping=c_ratio * c_dh),
                                         omegas, amplitude))
            / (amplitude / float(smooth.host_stiffness))
            for name, system in tuned.items()
        }
        i = int(np.flatnonzero(amplitudes == amplitude)[0])
        design_rows.append([amplitude, k_ratio, c_ratio, peaks["smoothed"], peaks["exact"],
                            rows[i][6]])
    write_csv(
        args.out / "exact_friction_paper_designs.csv",
        ["amplitude_N", "paper_k_over_k_DH", "paper_c_over_c_DH",
         "x_peak_over_A_K_smoothed", "x_peak_over_A_K_exact", "x_peak_retuned_exact"],
        design_rows,
    )
    print(_table(
        ["A [N]", "paper k/k_DH", "paper c/c_DH", "x/(A/K) smoothed", "x/(A/K) exact",
         "retuned, exact"],
        [[f"{r[0]:g}", f"{r[1]:g}", f"{r[2]:g}", f"{r[3]:.4f}", f"{r[4]:.4f}",
          f"{r[5]:.4f}"] for r in design_rows],
    ))

    # 3. the smoothed model's error against the exact one as the width shrinks
    host = float(smooth.host_frequency)
    error_rows = []
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for amplitude, ratio in WIDTH_POINTS:
        omega = ratio * host
        reference = tj.frequency_response(exact, omega, amplitude)
        errors = []
        for width in WIDTHS:
            response = tj.frequency_response(smooth.replace(friction_width=width), omega,
                                             amplitude)
            error = abs(float(response.x_max) / float(reference.x_max) - 1)
            errors.append(error if bool(response.converged) else np.nan)
            error_rows.append([amplitude, omega / (2 * math.pi), width, errors[-1],
                               float(reference.stick_fraction)])
        ax.loglog(WIDTHS, errors, "o-",
                  label=f"{amplitude:g} N at {ratio:g} f_n "
                        f"(stuck {float(reference.stick_fraction):.0%} of the period)")
    ax.set_xlabel("friction width [m/s]")
    ax.set_ylabel("|x_max smoothed / x_max exact - 1|")
    ax.set_title("Smoothed friction against exact Coulomb friction (paper's system)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    write_csv(args.out / "friction_width_error.csv",
              ["amplitude_N", "frequency_Hz", "friction_width_m_per_s",
               "x_peak_relative_error", "stick_fraction_exact"], error_rows)
    plot.save_figure(fig, args.out / "friction_width_error.png")
    for row in error_rows:
        print(f"A = {row[0]:g} N, {row[1]:.2f} Hz, width {row[2]:.1e} m/s: error {row[3]:.2e}")


if __name__ == "__main__":
    main()
