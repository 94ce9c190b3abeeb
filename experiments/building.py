"""A worked example: a 10-storey shear building under ground acceleration with a tuned
inerter damper (TID) between the ground and floor 1, its inerter with dry friction.

The building: equal storey masses of 3e5 kg, storey stiffnesses falling linearly to half
at the top, scaled to a first mode of 1 Hz, 2% damping in every mode. The TID: b = 5% of
the first mode's modal mass with the mode scaled to a unit displacement of floor 1, where
the TID acts (a mass ratio of 5% in the single-mode model; b is then 1.8 times the
building's mass, as an inerter's inertance may be), the paper's friction scaled to it
(ff = (20 / 75) b N), the spring and damper from floor 1 to the inerter's terminal, the
inerter from there to the ground. At each ground acceleration amplitude,
three tunings: the first mode's Den Hartog tuning, its exact single-mode H-infinity
tuning (Nishihara-Asami), and the retune of the whole structure with friction for that
amplitude (`tid_jax.retune`, on the roof's displacement). For each: the peak
roof displacement over the band and the peak drift of the storey that drifts most in
the first mode.

Writes building.csv and building.png to --out (default docs/figures/).
"""

import argparse
import os
from pathlib import Path

import jax
import numpy as np

STOREYS = 10
STOREY_MASS = 3.0e5  # kg
FIRST_MODE_HZ = 1.0
DAMPING_RATIO = 0.02
MASS_RATIO = 0.05  # b over the first modal mass
FRICTION_PER_INERTANCE = 20.0 / 75.0  # N/kg: the paper's ff / b
AMPLITUDES = (0.1, 0.2, 0.3, 0.5, 0.8, 1.2, 1.6)  # m/s2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", True)
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import tid_jax as tj

    tj.enable_compilation_cache()  # $TID_JAX_CACHE_DIR=off turns it off
    import matplotlib.pyplot as plt

    from tid_jax import plot
    from tid_jax._runtime._io import write_csv
    from tid_jax.cli._building import uncontrolled_peak

    shape = np.linspace(1.0, 0.5, STOREYS)
    masses = np.full(STOREYS, STOREY_MASS)
    probe = tj.Structure.shear_building(masses, shape, damping_ratio=DAMPING_RATIO)
    scale = (2 * np.pi * FIRST_MODE_HZ / probe.modes()[0][0]) ** 2
    structure = tj.Structure.shear_building(masses, shape * scale,
                                            damping_ratio=DAMPING_RATIO)
    unit = tj.BuildingTID(structure, 1.0, 0.0, 1.0, 0.0, load="ground")
    b = MASS_RATIO * float(unit.first_mode()[1])
    system = tj.BuildingTID(structure, b, FRICTION_PER_INERTANCE * b, 1.0, 0.0,
                            load="ground")
    amplitudes = np.asarray(AMPLITUDES)
    first_mode = structure.modes()[1][:, 0]
    storey = int(np.argmax(np.abs(np.diff(np.concatenate([[0.0], first_mode]))))) + 1
    drift = tj.Quantity("drift", storey)
    print(f"{STOREYS} storeys, first mode {FIRST_MODE_HZ} Hz; b = {b:.4g} kg, "
          f"ff = {float(system.friction_force):.4g} N; largest first-mode drift: "
          f"storey {storey}", flush=True)

    result = tj.retune(system, amplitudes, progress=lambda line: print(line, flush=True))
    tunings = tj.first_mode_tunings(system)
    designs = {"first-mode Den Hartog": [tunings["den_hartog"]] * amplitudes.size,
               "first-mode H-infinity": [tunings["h_infinity"]] * amplitudes.size,
               "retuned (whole structure)": list(zip(result.tid_stiffness,
                                                     result.tid_damping, strict=True))}
    roof = {name: np.asarray([
        float(tj.peaks(system.replace(tid_stiffness=k, tid_damping=c), None, [a]).x_peak[0])
        for a, (k, c) in zip(amplitudes, designs[name], strict=True)])
        for name in ("first-mode Den Hartog", "first-mode H-infinity")}
    roof["retuned (whole structure)"] = np.asarray(result.x_peak)
    drifts = {}
    for name, tuning in designs.items():
        drifts[name] = np.asarray([
            float(tj.peaks(system.replace(tid_stiffness=k, tid_damping=c), None, [a],
                           quantity=drift).x_peak[0])
            for a, (k, c) in zip(amplitudes, tuning, strict=True)])
        print(f"drifts: {name}", flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    header = ["amplitude_m_per_s2", "uncontrolled_roof_m", "retuned_converged"]
    bare = uncontrolled_peak(system, tj.Quantity(), np.asarray(tj.default_omegas(system)))
    for name in designs:
        key = name.split(" (")[0].replace("first-mode ", "").replace("-", "_").replace(
            " ", "_").lower()
        header += [f"{key}_k_N_per_m", f"{key}_c_N_s_per_m", f"{key}_roof_m",
                   f"{key}_drift_{storey}_m"]
    rows = []
    for i, a in enumerate(amplitudes):
        row = [a, a * bare]
        for name, tuning in designs.items():
            row += [tuning[i][0], tuning[i][1], roof[name][i], drifts[name][i]]
        rows.append([f"{float(v):.6g}" for v in row])
        rows[-1].insert(2, str(bool(result.converged[i])))
    write_csv(args.out / "building.csv", header, rows)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), layout="constrained")
    for name in designs:
        axes[0].plot(amplitudes, 100 * roof[name] / amplitudes, marker="o", markersize=3,
                     label=name)
        axes[1].plot(amplitudes, 100 * drifts[name] / amplitudes, marker="o", markersize=3,
                     label=name)
    axes[0].set(xlabel="ground acceleration amplitude (m/s2)",
                ylabel="peak roof displacement / amplitude (cm per m/s2)",
                title="roof displacement")
    axes[1].set(xlabel="ground acceleration amplitude (m/s2)",
                ylabel=f"peak storey {storey} drift / amplitude (cm per m/s2)",
                title=f"storey {storey} drift")
    for ax in axes:
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{STOREYS}-storey building, TID from the ground to floor 1, "
                 f"b = {MASS_RATIO:.0%} of the first modal mass, ff = (20/75 N/kg) b")
    plot.save_figure(fig, args.out / "building.png")
    print(f"wrote {args.out / 'building.csv'} and {args.out / 'building.png'}")
    for i, a in enumerate(amplitudes):
        print(f"A = {a:4.2f} m/s2: roof {100 * result.x_peak[i]:.3g} cm retuned, "
              f"{100 * roof['first-mode H-infinity'][i]:.3g} cm H-infinity, "
              f"{100 * roof['first-mode Den Hartog'][i]:.3g} cm Den Hartog"
              + ("" if result.converged[i] else " (retune not converged)"))


if __name__ == "__main__":
    main()
