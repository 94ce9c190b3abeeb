"""What the real inerter device means for design (paper section 6): the paper's TID
retuned at 200, 400 and 600 N with four devices, from the ideal inerter to one with a
terminal mass, a compliant connection and backlash.

Devices (b = 75 kg and ff = 20 N throughout, SI units):
- ideal: the paper's model, b y'' + ff sgn(y');
- + terminal mass: 2 kg moving with the driven terminal (the paper's Penske unit);
- + compliance: the screw, nut and mounts as a series stiffness of 3e5 N/m, with which
  the inertance resonates at 10 Hz, 2.5 times the host frequency;
- + backlash: 0.2 mm of total free play in that connection, about a tenth of the
  inerter's stroke at 200 N.

For each: the peak host displacement with Den Hartog's tuning (the design the paper
built) and the retuned k, c, peak and stroke. Writes device_design.csv and
device_design.png to --out (default docs/figures/) and prints the table."""

import argparse
import os
from pathlib import Path

import jax
import numpy as np

AMPLITUDES = (200.0, 400.0, 600.0)  # N
TERMINAL_MASS = 2.0  # kg
SERIES_STIFFNESS = 3e5  # N/m
BACKLASH = 2e-4  # m
DEVICES = {
    "ideal": {},
    "+ terminal mass": dict(terminal_mass=TERMINAL_MASS),
    "+ compliance": dict(terminal_mass=TERMINAL_MASS, series_stiffness=SERIES_STIFFNESS),
    "+ backlash": dict(terminal_mass=TERMINAL_MASS, series_stiffness=SERIES_STIFFNESS,
                       backlash=BACKLASH),
}
COLUMNS = ("device", "amplitude_N", "x_den_hartog_over_A_K", "x_retuned_over_A_K",
           "k_over_k_den_hartog", "c_over_c_den_hartog", "stroke_retuned_m", "status")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    jax.config.update("jax_enable_x64", True)
    # equinox's run-time checks as NaN (read when the library imports equinox): programs
    # holding them are then kept in the compilation cache; every solve reports its status
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import tid_jax as tj

    out = parser.parse_args().out
    tj.enable_compilation_cache()  # $TID_JAX_CACHE_DIR=off turns it off
    from tid_jax import plot
    from tid_jax._runtime._io import write_csv

    paper = tj.paper_system(friction_width=None)  # the relative width of docs/figures
    k_dh, c_dh = float(paper.tid_stiffness), float(paper.tid_damping)
    amplitudes = np.asarray(AMPLITUDES)
    static = amplitudes / float(paper.host_stiffness)
    rows, curves = [], {}
    for name, device in DEVICES.items():
        print(f"retuning with the device {name}")
        result = tj.retune(paper.replace(**device), amplitudes)
        curves[name] = (amplitudes, np.asarray(result.x_peak_initial) / static,
                        np.asarray(result.x_peak) / static,
                        np.asarray(result.tid_stiffness) / k_dh,
                        np.asarray(result.tid_damping) / c_dh)
        rows += [[name, float(amplitude), *(float(curve[i]) for curve in curves[name][1:]),
                  float(result.y_peak[i]), result.status_messages()[i]]
                 for i, amplitude in enumerate(amplitudes)]

    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "device_design.csv", COLUMNS, rows)
    print("| device | A [N] | x/(A/K) Den Hartog | x/(A/K) retuned | k/k_DH | c/c_DH "
          "| stroke [cm] | status |")
    print("| --- |" + " ---: |" * 6 + " --- |")
    for name, amplitude, x_dh, x, k, c, stroke, status in rows:
        print(f"| {name} | {amplitude:g} | {x_dh:.3f} | {x:.3f} | {k:.3f} | {c:.3f} | "
              f"{100 * stroke:.2f} | {status} |")
    plot.save_figure(plot.plot_device_designs(
        curves, title="The paper's TID with the real device: Den Hartog's tuning and the "
        "retune"), out / "device_design.png")


if __name__ == "__main__":
    main()
