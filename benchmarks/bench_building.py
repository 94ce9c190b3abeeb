"""Per-orbit cost of the steady states of an n-storey shear building with a tuned inerter
damper (TID) between the ground and floor 1, against the number of storeys, side by side
in one run with a scipy LSODA baseline; and how the cost grows with n (a power law
t ~ n^p fitted over the measured n, one exponent p per method).

Run from the repository root:

    python benchmarks/bench_building.py [--storeys 1,3,10,30] [--points 24] [--retune]

The building is that of `experiments/building.py` with n storeys: equal storey masses
(3e5 kg), storey stiffnesses falling linearly to half at the top, scaled to a 1 Hz first
mode, 2% modal damping; b = 5% of the first modal mass, ff = (20/75) b N, the first
mode's exact H-infinity k and c; ground acceleration 0.5 m/s2 at `--points` frequencies
evenly over 0.7..1.3 times the first mode; the peak roof displacement.

- tid_jax: warm `frequency_response` (compiled by a first call, then the best of 3), with
  exact Coulomb friction (`friction_width=0`) and smoothed (`friction_width=None`:
  tanh(r'/w_s), w_s = 0.02 omega A d_ref).
- LSODA: `scipy.integrate.solve_ivp(method="LSODA")`, one call per point, on the same
  smoothed model as a first-order system (x, r, x', r') with a precomputed Mg^-1 and an
  analytic Jacobian, rtol 1e-6, atol scaled to the linear motion, from the frictionless
  linear steady state over P forcing periods; the peak over 512 samples of the last
  period. P is, for each n, the smallest of 10, 20, 40, 80, 160 whose last-period peaks
  all match tid_jax's converged smoothed orbits within 1e-3; the time is that of the run
  at P. Where the loop over all points would take longer than `--lsoda-budget` seconds
  (estimated at 40 periods), it is timed on `--lsoda-subset` points spread over the band.
- The smoothed rows use the default settings: the integrator is chosen automatically
  (`SolverSettings.implicit=None`); the table says which one was.

`--retune` also times `tid_jax.retune` of the 10-storey building (exact friction,
default settings) at `--retune-amplitudes`, cold (first call in the process, compiling)
and warm.
Prints markdown.
"""

import argparse
import os
import sys
import time

os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import tid_jax as tj  # noqa: E402
from tid_jax._model._system import FRICTION_WIDTH_RATIO  # noqa: E402
from tid_jax._orbit._stiffness import for_points  # noqa: E402
from tid_jax._response import batched  # noqa: E402

STOREY_MASS = 3.0e5  # kg
FIRST_MODE_HZ = 1.0
DAMPING_RATIO = 0.02
MASS_RATIO = 0.05  # b over the first modal mass
FRICTION_RATIO = 20.0 / 75.0  # ff / b, N/kg
AMPLITUDE = 0.5  # m/s2
BAND = (0.7, 1.3)  # times the first mode
ROOF = tj.Quantity("displacement")
RTOL = 1e-6
MATCH = 1e-3
CANDIDATE_PERIODS = (10, 20, 40, 80, 160)
ESTIMATE_PERIODS = 40  # periods of the run that estimates LSODA's time per point
SAMPLES = 512  # LSODA output samples in the last period
REPEATS = 3
RETUNE_STOREYS = 10


# --- the building, in numpy -------------------------------------------------------------

def shear_matrices(stiffnesses):
    """Storey masses and stiffnesses -> (M, K) of the shear building, floor 1 first."""
    n = len(stiffnesses)
    above = np.append(stiffnesses[1:], 0.0)
    stiffness = (np.diag(stiffnesses + above) - np.diag(stiffnesses[1:], 1)
                 - np.diag(stiffnesses[1:], -1))
    return np.diag(np.full(n, STOREY_MASS)), stiffness


def modes(mass, stiffness):
    """Natural frequencies (rad/s, ascending) and mass-normalised mode shapes."""
    values, shapes = scipy.linalg.eigh(stiffness, mass)
    return np.sqrt(values), shapes


def storey_stiffnesses(n):
    """Stiffnesses falling linearly to half at the top, scaled to the first mode."""
    shape = np.linspace(1.0, 0.5, n)
    first = modes(*shear_matrices(shape))[0][0]
    return shape * (2 * np.pi * FIRST_MODE_HZ / first) ** 2


def modal_damping(mass, stiffness):
    omegas, shapes = modes(mass, stiffness)
    weighted = mass @ shapes
    return weighted @ np.diag(2 * DAMPING_RATIO * omegas) @ weighted.T


def coupled(block, corner, coupling):
    """[[block, coupling], [coupling^T, corner]]."""
    return np.block([[block, coupling[:, None]], [coupling[None, :], np.array([[corner]])]])


def generalised(stiffnesses, b, k, c):
    """(Mg, Cg, Kg, G) over (x_1..x_n, r): spring on floor 1, inerter on the ground."""
    mass, stiffness = shear_matrices(stiffnesses)
    n = mass.shape[0]
    d = np.eye(n)[0]
    mg = coupled(mass, b, np.zeros(n))
    kg = coupled(stiffness + k * np.outer(d, d), k, -k * d)
    cg = coupled(modal_damping(mass, stiffness) + c * np.outer(d, d), c, -c * d)
    g = -np.append(mass @ np.ones(n), 0.0)
    return mg, cg, kg, g


def static_scale(stiffnesses):
    """d_ref = max |K^-1 M 1|, m per m/s2."""
    mass, stiffness = shear_matrices(stiffnesses)
    return float(np.max(np.abs(np.linalg.solve(stiffness, mass @ np.ones(len(stiffnesses))))))


# --- the building, in tid_jax -----------------------------------------------------------

def tid_systems(stiffnesses):
    """The exact-friction and smoothed `BuildingTID`s, H-infinity tuned."""
    masses = np.full(len(stiffnesses), STOREY_MASS)
    structure = tj.Structure.shear_building(masses, stiffnesses, damping_ratio=DAMPING_RATIO)
    probe = tj.BuildingTID(structure, 1.0, 0.0, 1.0, 0.0, load="ground")
    b = MASS_RATIO * probe.first_mode()[1]
    system = tj.BuildingTID(structure, b, FRICTION_RATIO * b, 1.0, 0.0, load="ground")
    k, c = tj.first_mode_tunings(system)["h_infinity"]
    exact = system.replace(tid_stiffness=k, tid_damping=c)
    return exact, exact.replace(friction_width=None)


def numpy_model(stiffnesses, system):
    """The baseline's matrices, built in numpy and checked against the library's."""
    parameters = (float(system.inertance), float(system.tid_stiffness),
                  float(system.tid_damping))
    model = generalised(stiffnesses, *parameters)
    library = [np.asarray(m) for m in system.generalised_matrices()]
    library.append(np.asarray(system.load_vector()))
    for mine, theirs in zip(model, library, strict=True):
        if not np.allclose(mine, theirs, rtol=1e-9, atol=1e-9 * np.max(np.abs(theirs))):
            raise RuntimeError("numpy model differs from tid_jax's generalised matrices")
    return model


# --- tid_jax timing ---------------------------------------------------------------------

def tid_run(system, omegas):
    r = tj.frequency_response(system, omegas, [AMPLITUDE], quantity=ROOF)
    return np.asarray(r.x_max)[0], np.asarray(r.converged)[0]


def best_time(function, repeats=REPEATS):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def measure_tid(system, omegas):
    """Warm per-orbit seconds, peaks and converged count of one `BuildingTID`."""
    peaks, converged = tid_run(system, omegas)  # compiles
    seconds = best_time(lambda: tid_run(system, omegas))
    return dict(per_orbit=seconds / omegas.size, peaks=peaks, converged=int(converged.sum()))


# --- the LSODA baseline -----------------------------------------------------------------

class Lsoda:
    """The smoothed model as z' = J0 z + q A sin(w t) - h ff tanh(r'/w_s), z = (u, u')."""

    def __init__(self, model, friction_force, d_ref):
        mg, cg, kg, g = model
        self.model, self.m = model, mg.shape[0]
        inverse = np.linalg.inv(mg)
        zero, eye = np.zeros((self.m, self.m)), np.eye(self.m)
        self.j0 = np.block([[zero, eye], [-inverse @ kg, -inverse @ cg]])
        self.q = np.concatenate([np.zeros(self.m), inverse @ g])
        self.h = np.concatenate([np.zeros(self.m), inverse[:, -1]])
        self.ff, self.d_ref = friction_force, d_ref

    def linear_start(self, omega):
        """Frictionless steady state at t = 0 (a = A Im e^{i w t}) and its size per state."""
        mg, cg, kg, g = self.model
        u = AMPLITUDE * np.linalg.solve(kg - omega**2 * mg + 1j * omega * cg, g + 0j)
        z0 = np.concatenate([u.imag, omega * u.real])
        size = np.concatenate([np.abs(u), omega * np.abs(u)])
        return z0, np.maximum(size, 1e-6 * np.max(size))

    def peak(self, omega, periods):
        """Peak |roof displacement| over the last of `periods` periods (NaN: failed)."""
        width = FRICTION_WIDTH_RATIO * omega * AMPLITUDE * self.d_ref
        z0, size = self.linear_start(omega)
        period = 2 * np.pi / omega
        t_end = periods * period
        t_eval = t_end - period + period * np.arange(SAMPLES) / SAMPLES

        def rhs(t, z):
            friction = self.ff * np.tanh(z[-1] / width)
            return self.j0 @ z + self.q * (AMPLITUDE * np.sin(omega * t)) - self.h * friction

        def jac(t, z):
            slope = self.ff * (1 - np.tanh(z[-1] / width) ** 2) / width
            out = self.j0.copy()
            out[:, -1] -= self.h * slope
            return out

        sol = solve_ivp(rhs, (0.0, t_end), z0, method="LSODA", jac=jac, rtol=RTOL,
                        atol=0.1 * RTOL * size, t_eval=t_eval)
        if sol.status != 0 or sol.y.shape[1] != SAMPLES:
            return np.nan
        return periodic_peak(sol.y[self.m - 2])

    def peaks(self, omegas, periods):
        return np.array([self.peak(float(w), periods) for w in omegas])


def periodic_peak(samples):
    """Largest |sample| of a periodic sequence, refined by a parabola."""
    values = np.abs(samples)
    i = int(np.argmax(values))
    left, mid, right = values[i - 1], values[i], values[(i + 1) % values.size]
    curvature = left - 2 * mid + right
    return mid - (right - left) ** 2 / (8 * curvature) if curvature < 0 else mid


def max_rel_difference(values, reference):
    """Over the points where tid_jax converged; an LSODA failure counts as inf."""
    ok = np.isfinite(reference)
    if not np.any(ok):
        return np.nan
    rel = np.abs(values[ok] - reference[ok]) / np.abs(reference[ok])
    return float(np.max(np.where(np.isfinite(rel), rel, np.inf)))


def lsoda_points(lsoda, omegas, budget_s, subset):
    """The indices LSODA is timed on: all, or `subset` spread over the band where the
    loop would exceed `budget_s` (estimated from one point at `ESTIMATE_PERIODS`)."""
    start = time.perf_counter()
    lsoda.peak(float(omegas[0]), ESTIMATE_PERIODS)
    estimate = (time.perf_counter() - start) * omegas.size
    if estimate <= budget_s or subset >= omegas.size:
        return np.arange(omegas.size)
    return np.unique(np.round(np.linspace(0, omegas.size - 1, subset)).astype(int))


def measure_lsoda(lsoda, omegas, reference, budget_s, subset):
    """LSODA at the smallest candidate P whose peaks all match `reference` within MATCH
    (else the largest), timed at that P."""
    index = lsoda_points(lsoda, omegas, budget_s, subset)
    tried = []
    for periods in CANDIDATE_PERIODS:
        start = time.perf_counter()
        peaks = lsoda.peaks(omegas[index], periods)
        seconds = time.perf_counter() - start
        tried.append((periods, max_rel_difference(peaks, reference[index])))
        print(f"  LSODA {periods} periods: max rel. difference {tried[-1][1]:.1e}",
              file=sys.stderr, flush=True)
        if tried[-1][1] <= MATCH:
            break
    return dict(per_orbit=seconds / index.size, points=index.size, periods=periods,
                matched=tried[-1][1] <= MATCH, tried=tried, difference=tried[-1][1],
                converged=int(np.sum(np.isfinite(peaks))))


# --- one building -----------------------------------------------------------------------

class Building:
    """The n-storey building: its tid_jax systems, numpy model and frequencies."""

    def __init__(self, n, points):
        self.n = n
        stiffnesses = storey_stiffnesses(n)
        self.exact, self.smoothed = tid_systems(stiffnesses)
        model = numpy_model(stiffnesses, self.exact)
        self.lsoda = Lsoda(model, float(self.exact.friction_force), static_scale(stiffnesses))
        first = self.exact.first_mode()[0]
        self.omegas = first * np.linspace(*BAND, points)


def smoothed_integrator(building):
    """The integrator the automatic choice takes for the smoothed building's points."""
    omegas = building.omegas
    chosen = for_points(tj.SolverSettings(), batched(building.smoothed, omegas.size), omegas,
                        np.full(omegas.shape, AMPLITUDE))
    return "Kvaerno5" if chosen.implicit else "Tsit5"


def measure(building, args):
    print(f"n = {building.n} ...", file=sys.stderr, flush=True)
    exact = measure_tid(building.exact, building.omegas)
    smoothed = measure_tid(building.smoothed, building.omegas)
    smoothed["integrator"] = smoothed_integrator(building)
    lsoda = measure_lsoda(building.lsoda, building.omegas, smoothed["peaks"],
                          args.lsoda_budget, args.lsoda_subset)
    return dict(n=building.n, exact=exact, smoothed=smoothed, lsoda=lsoda)


# --- output -----------------------------------------------------------------------------

def growth_exponent(storeys, per_orbit):
    """p of t ~ n^p, least squares in log-log (NaN with fewer than two n)."""
    if len(set(storeys)) < 2:
        return np.nan
    return float(np.polyfit(np.log(storeys), np.log(per_orbit), 1)[0])


def row(result, points):
    ex, sm, ls = result["exact"], result["smoothed"], result["lsoda"]
    ms = lambda seconds: f"{seconds * 1e3:.3g}"
    lsoda_ms = ms(ls["per_orbit"])
    if ls["points"] < points:
        lsoda_ms += f" ({ls['points']} of {points} points)"
    periods = f"{ls['periods']}" + ("" if ls["matched"] else " (not matched)")
    return (f"| {result['n']} | {2 * (result['n'] + 1)} | {ms(ex['per_orbit'])} | "
            f"{ms(sm['per_orbit'])} ({sm['integrator']}) | {periods} | {lsoda_ms} | "
            f"{ls['per_orbit'] / ex['per_orbit']:.3g}x | "
            f"{ls['per_orbit'] / sm['per_orbit']:.3g}x | {ls['difference']:.1e} | "
            f"exact {ex['converged']}/{points}, smoothed {sm['converged']}/{points}, "
            f"LSODA {ls['converged']}/{ls['points']} |")


def table(results, points):
    lines = [
        f"Shear building, TID from the ground to floor 1, ground acceleration "
        f"{AMPLITUDE} m/s2, {points} frequencies over {BAND[0]}..{BAND[1]} times the first "
        f"mode; peak roof displacement. tid_jax: warm `frequency_response`, best of "
        f"{REPEATS}, default settings (smoothed: the integrator chosen automatically). "
        f"LSODA: one `solve_ivp` call per point, rtol {RTOL:g}, from the linear steady "
        f"state over the fewest periods P of {', '.join(map(str, CANDIDATE_PERIODS))} whose "
        f"last-period peaks match tid_jax's smoothed orbits within {MATCH:g}.",
        "",
        "| storeys | states | tid_jax exact ms/orbit | tid_jax smoothed ms/orbit | LSODA "
        "periods | LSODA ms/orbit | LSODA / exact | LSODA / smoothed | LSODA max rel. "
        "difference to tid_jax smoothed | converged |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [row(result, points) for result in results]
    storeys = [result["n"] for result in results]
    lines.append("")
    for name, key in (("tid_jax exact", "exact"), ("tid_jax smoothed", "smoothed"),
                      ("LSODA", "lsoda")):
        p = growth_exponent(storeys, [result[key]["per_orbit"] for result in results])
        lines.append(f"- {name}: time per orbit ~ n^p, p = {p:.2f}")
    lines.append("- LSODA periods tried: " + "; ".join(
        f"n = {r['n']}: " + ", ".join(f"{p}: {d:.1e}" for p, d in r["lsoda"]["tried"])
        for r in results))
    return lines


# --- the retune -------------------------------------------------------------------------

def time_retune(amplitudes):
    exact, _ = tid_systems(storey_stiffnesses(RETUNE_STOREYS))

    def run():
        return tj.retune(exact, amplitudes)

    start = time.perf_counter()
    run()
    cold = time.perf_counter() - start
    start = time.perf_counter()
    result = run()
    warm = time.perf_counter() - start
    k, c = tj.first_mode_tunings(exact)["h_infinity"]
    h_infinity = tj.peaks(exact.replace(tid_stiffness=k, tid_damping=c), None, amplitudes)
    ratio = np.asarray(result.x_peak) / np.asarray(h_infinity.x_peak)
    return [f"`retune`, {RETUNE_STOREYS} storeys (exact friction, default "
            f"settings), {len(amplitudes)} amplitudes {amplitudes[0]:.3g}.."
            f"{amplitudes[-1]:.3g} m/s2: cold {cold:.1f} s (compiling), warm {warm:.1f} s; "
            f"converged {int(np.sum(result.converged))}/{len(amplitudes)}; retuned peak / "
            f"first-mode H-infinity peak {np.nanmin(ratio):.2f}..{np.nanmax(ratio):.2f}."]


# --- main -------------------------------------------------------------------------------

def parse():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--storeys", default="1,3,10,30",
                        help="comma-separated storey counts ('' : no table)")
    parser.add_argument("--points", type=int, default=24, help="frequencies")
    parser.add_argument("--lsoda-budget", type=float, default=300.0,
                        help="s; a longer LSODA loop is timed on a subset")
    parser.add_argument("--lsoda-subset", type=int, default=6)
    parser.add_argument("--retune", action="store_true")
    parser.add_argument("--retune-amplitudes", type=float, nargs="+",
                        default=list(np.geomspace(0.05, 1.6, 12)), help="m/s2")
    return parser.parse_args()


def run_table(args):
    storeys = [int(s) for s in args.storeys.split(",") if s.strip()]
    results = [measure(Building(n, args.points), args) for n in storeys]
    return table(results, args.points)


def main():
    args = parse()
    retune = time_retune(np.asarray(args.retune_amplitudes)) if args.retune else []
    lines = run_table(args) if args.storeys.strip() else []
    print("\n".join(lines + ([""] if lines and retune else []) + retune))


if __name__ == "__main__":
    main()
