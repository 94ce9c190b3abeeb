"""Stability of the virtual real-time dynamic substructuring test of the inerter (paper
section 5): the largest actuator delay for which the test stays stable, against the
guessed-to-true inertance ratio b_g / b, at A = 200 N and 4 Hz with a 1 kHz controller.

Curves: error feedback (eq. (16)) without prediction, with forward prediction, and with
the paper's approximation b_g y*'' ~ -b_g omega^2 y* (with prediction); and the
conventional scheme (eqs. (13)-(14)), for which b_g plays no part.

Writes rtds_stability_map.csv and .png to --out (default docs/figures/)."""

import argparse
import math
import os
from pathlib import Path

import jax
import numpy as np

AMPLITUDE = 200.0  # N
FREQUENCY_HZ = 4.0
CURVES = (
    ("error feedback, no prediction", dict(scheme="error_feedback")),
    ("error feedback, forward prediction", dict(scheme="error_feedback",
                                                prediction="harmonic")),
    ("error feedback, -b_g w^2 y* guess, prediction", dict(scheme="error_feedback",
                                                           prediction="harmonic",
                                                           guessed_force="harmonic")),
    ("conventional", dict(scheme="conventional")),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    parser.add_argument("--max-delay-ms", type=float, default=100.0)
    parser.add_argument("--delay-step-ms", type=float, default=2.0)
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    # equinox's run-time checks as NaN (read when the library imports equinox): programs
    # holding them are then kept in the compilation cache; every solve reports its status
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import tid_jax as tj

    tj.enable_compilation_cache()  # $TID_JAX_CACHE_DIR=off turns it off
    from tid_jax import plot
    from tid_jax._runtime._io import write_csv

    system = tj.paper_system(friction_width=None)  # the real-time test smooths the friction
    ratios = np.round(np.arange(0.3, 2.001, 0.1), 10)
    delays = 1e-3 * np.arange(0.0, args.max_delay_ms + 1e-9, args.delay_step_ms)
    omega = 2 * math.pi * FREQUENCY_HZ
    maps = [
        tj.substructuring_stability(system, omega, AMPLITUDE,
                                    guessed_inertance=ratios * float(system.inertance),
                                    delay=delays, **options)
        for _, options in CURVES
    ]

    write_csv(
        args.out / "rtds_stability_map.csv",
        ["curve", "guess_ratio", "largest_stable_delay_s", "stable_delays_of_grid",
         "max_delay_tried_s"],
        [[label, r, float(m.largest_stable_delay[i]), int(np.sum(m.stable[i])), delays[-1]]
         for (label, _), m in zip(CURVES, maps, strict=True) for i, r in enumerate(ratios)],
    )
    plot.save_figure(
        plot.plot_substructuring_stability(
            [(label, ratios, m.largest_stable_delay)
             for (label, _), m in zip(CURVES, maps, strict=True)],
            max_delay=delays[-1],
            title=f"Largest stable delay, A = {AMPLITUDE:g} N at {FREQUENCY_HZ:g} Hz, "
                  "1 kHz controller",
        ),
        args.out / "rtds_stability_map.png",
    )
    for (label, _), m in zip(CURVES, maps, strict=True):
        largest = np.asarray(m.largest_stable_delay)
        print(label + ": " + ", ".join(
            f"{r:.1f}:{'none' if d < 0 else f'{1e3 * d:g} ms'}"
            for r, d in zip(ratios, largest, strict=True)))
    print(f"wrote {args.out}/rtds_stability_map.{{csv,png}}")


if __name__ == "__main__":
    main()
