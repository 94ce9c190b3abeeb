"""Figure 5 of the paper: peak host displacement x and inerter displacement y over A/K
against forcing frequency, for the paper's twelve forcing amplitudes (100-3000 N) with the
Den Hartog-tuned dry-friction TID, beside the linear (frictionless) TID.

Writes fig5_frequency_response.csv and .png to --out (default docs/figures/)."""

import argparse
import math
import os
from pathlib import Path

import jax
import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    parser.add_argument("--n-frequencies", type=int, default=151)
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
    omegas = np.asarray(tj.default_omegas(system, args.n_frequencies))
    amplitudes = np.asarray(tj.PAPER_AMPLITUDES)
    response = tj.frequency_response(system, omegas, amplitudes)
    static = amplitudes[:, None] / float(system.host_stiffness)
    x_norm = np.asarray(response.x_max) / static
    y_norm = np.asarray(response.y_max) / static
    linear = tj.linear_receptance(system, omegas)
    x_linear = np.abs(np.asarray(linear.host)) * float(system.host_stiffness)
    y_linear = np.abs(np.asarray(linear.inerter)) * float(system.host_stiffness)
    converged = np.asarray(response.converged)
    frequencies_hz = omegas / (2 * math.pi)

    write_csv(
        args.out / "fig5_frequency_response.csv",
        [
            "amplitude_N",
            "frequency_Hz",
            "x_over_A_K",
            "y_over_A_K",
            "x_linear_over_A_K",
            "y_linear_over_A_K",
            "converged",
        ],
        [
            [a, f, x_norm[i, j], y_norm[i, j], x_linear[j], y_linear[j], bool(converged[i, j])]
            for i, a in enumerate(amplitudes)
            for j, f in enumerate(frequencies_hz)
        ],
    )
    plot.save_figure(
        plot.plot_frequency_response(
            frequencies_hz,
            amplitudes,
            x_norm,
            y_norm,
            linear=(frequencies_hz, x_linear, y_linear),
            host_frequency_hz=float(system.host_frequency) / (2 * math.pi),
            title="Paper's system with a Den Hartog-tuned TID, ff = 20 N (paper Figure 5)",
        ),
        args.out / "fig5_frequency_response.png",
    )
    print(
        f"{converged.sum()}/{converged.size} steady states converged; wrote {args.out}/"
        "fig5_frequency_response.{csv,png}"
    )


if __name__ == "__main__":
    main()
