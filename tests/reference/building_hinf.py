"""Derivative-free H-infinity tuning of a TID on a multi-storey structure (SI units).

Model: see ``building_linear`` (structure ``M``, ``K``, ``C``; spring ``k`` and damper
``c`` from ``spring_floor`` to the terminal, inerter ``b`` from the terminal to
``inerter_floor``; force or ground load; frictionless).  The objective is the peak over
frequency of the chosen response amplitude per unit load amplitude,
``P(k, c) = max_w |H(w; k, c)|``, from the closed-form complex solve.

Method:

* inner peak (``peak``): ``|H|`` on a dense log-spaced grid over the band (default
  0.3..3 times the first undamped natural frequency of the bare structure, 3000
  points); every grid local maximum is polished with
  ``scipy.optimize.minimize_scalar(method="bounded")`` between its grid neighbours;
  the largest is the peak (relative accuracy ~1e-13; a maximum at a band edge is
  reported with ``at_edge``).
* outer search (``h_infinity_search``): ``scipy.optimize.minimize`` with Nelder-Mead on
  ``log P`` over ``(log k, log c)`` with tight tolerances, restarted from its own result
  until it stops improving.  Nelder-Mead copes with the non-smooth minimax optimum,
  where the two resonance peaks are equal.

Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

try:
    from .building_linear import (
        _quantity,
        _solve,
        generalised_load,
        generalised_matrices,
        natural_frequencies,
    )
except ImportError:  # run as a script from this folder
    from building_linear import (
        _quantity,
        _solve,
        generalised_load,
        generalised_matrices,
        natural_frequencies,
    )

__all__ = ["default_band", "h_infinity_search", "peak"]


def default_band(M, K):
    """(0.3 w1, 3 w1) [rad/s], w1 the first undamped frequency of the bare structure."""
    w1 = natural_frequencies(M, K)[0][0]
    return 0.3 * w1, 3.0 * w1


def _amplitude_function(M, K, C, b, k, c, spring_floor, inerter_floor, load, pattern, kind,
                        floor, cp, mt):
    """Vectorised w -> |H(w)| with the matrices built once."""
    Mg, Cg, Kg = generalised_matrices(M, K, C, b=b, k=k, c=c, spring_floor=spring_floor,
                                      inerter_floor=inerter_floor, cp=cp, mt=mt)
    G = generalised_load(M, load=load, pattern=pattern, inerter_floor=inerter_floor, mt=mt)
    n = len(G) - 1

    def amp(w):
        return np.abs(_quantity(w, _solve(w, Mg, Cg, Kg, G), n, load=load, kind=kind,
                                floor=floor))

    return amp


def _polished_maxima(amp, grid):
    """All local maxima (omega, value) of amp, from the grid, polished; plus an edge flag."""
    a = amp(grid)
    inner = np.nonzero((a[1:-1] >= a[:-2]) & (a[1:-1] >= a[2:]))[0] + 1
    found = []
    for i in inner:
        res = minimize_scalar(lambda w: -float(amp(w)), bounds=(grid[i - 1], grid[i + 1]),
                              method="bounded", options={"xatol": 1e-12 * grid[i]})
        w, v = (res.x, -res.fun) if -res.fun >= a[i] else (grid[i], a[i])
        found.append((float(w), float(v)))
    at_edge = False
    for i, j in ((0, 1), (-1, -2)):
        if a[i] > a[j] and (not found or a[i] > max(v for _, v in found)):
            found.append((float(grid[i]), float(a[i])))
            at_edge = True
    found.sort(key=lambda p: -p[1])
    return found, at_edge


def peak(M, K, C, *, b, k, c, spring_floor, inerter_floor, load="force", pattern=None,
         kind="displacement", floor=None, band=None, n_grid=3000, cp=0.0, mt=0.0):
    """Peak over w in ``band`` of the response amplitude per unit A, for given (k, c).

    Returns a dict: ``peak`` (largest maximum), ``frequencies`` [rad/s] and ``values``
    of all local maxima (largest first), ``at_edge`` (the largest is at a band edge).
    """
    amp = _amplitude_function(M, K, C, b, k, c, spring_floor, inerter_floor, load, pattern,
                              kind, floor, cp, mt)
    lo, hi = default_band(M, K) if band is None else band
    found, at_edge = _polished_maxima(amp, np.geomspace(lo, hi, n_grid))
    return dict(peak=found[0][1], frequencies=[w for w, _ in found],
                values=[v for _, v in found], at_edge=at_edge)


def h_infinity_search(M, K, C, *, b, spring_floor, inerter_floor, load, pattern=None,
                      kind="displacement", floor=None, start, band=None, n_grid=3000,
                      cp=0.0, mt=0.0, max_restarts=30, simplex_step=0.1):
    """(k, c) [N/m, N s/m] minimising the peak response; Nelder-Mead from ``start``.

    Returns a dict: ``k``, ``c``, ``peak`` (per unit A), ``frequencies`` (the two largest
    peak frequencies [rad/s], ascending), ``values`` (their peak values), ``nfev``,
    ``restarts``.
    """
    lo, hi = default_band(M, K) if band is None else band
    grid = np.geomspace(lo, hi, n_grid)

    def objective(p):
        k, c = np.exp(p)
        amp = _amplitude_function(M, K, C, b, k, c, spring_floor, inerter_floor, load,
                                  pattern, kind, floor, cp, mt)
        return math.log(_polished_maxima(amp, grid)[0][0][1])

    x = np.log(np.asarray(start, float))
    best = objective(x)
    nfev, restarts = 1, 0
    step = simplex_step
    for attempt in range(1, max_restarts + 1):
        restarts = attempt
        simplex = np.vstack([x, x + [step, 0.0], x + [0.0, step]])
        res = minimize(objective, x, method="Nelder-Mead",
                       options=dict(xatol=1e-10, fatol=1e-13, maxiter=20000, maxfev=20000,
                                    initial_simplex=simplex))
        nfev += res.nfev
        gain = best - res.fun
        if res.fun < best:
            x, best = res.x, res.fun
        if gain <= 1e-15:
            break
        step = max(min(step, 10.0 * float(np.max(np.abs(res.final_simplex[0][1:] - res.x)))),
                   1e-3)
    k, c = np.exp(x)
    info = peak(M, K, C, b=b, k=k, c=c, spring_floor=spring_floor, inerter_floor=inerter_floor,
                load=load, pattern=pattern, kind=kind, floor=floor, band=(lo, hi),
                n_grid=n_grid, cp=cp, mt=mt)
    two = sorted(zip(info["frequencies"][:2], info["values"][:2], strict=True))
    return dict(k=float(k), c=float(c), peak=info["peak"], frequencies=[w for w, _ in two],
                values=[v for _, v in two], nfev=int(nfev), restarts=int(restarts))


def _demo():
    import time

    try:
        from .building_linear import modal_damping, shear_building
        from .hinf import h_infinity_optimum
    except ImportError:
        from building_linear import modal_damping, shear_building
        from hinf import h_infinity_optimum

    # 1-storey host: compare with the exact two-equal-peak optimum of hinf.py
    Mh, bh = 1500.0, 75.0
    Kh = Mh * (2 * math.pi * 4.0) ** 2
    Ch = 2 * 0.02 * math.sqrt(Kh * Mh)
    k_ex, c_ex, p_ex = h_infinity_optimum(Mh, Kh, Ch, bh, verify=False)
    for start in [(0.8 * k_ex, 1.5 * c_ex), (1.2 * k_ex, 0.6 * c_ex)]:
        t0 = time.perf_counter()
        r = h_infinity_search([[Mh]], [[Kh]], [[Ch]], b=bh, spring_floor=1, inerter_floor=0,
                              load="force", start=start)
        dt = time.perf_counter() - t0
        print(f"1-storey: peak*K = {r['peak'] * Kh:.12g} (hinf.py {p_ex:.12g}, rel "
              f"{r['peak'] * Kh / p_ex - 1:.2e}); k rel {r['k'] / k_ex - 1:.1e}, "
              f"c rel {r['c'] / c_ex - 1:.1e}; nfev {r['nfev']}, {dt:.2f} s")

    # 3-storey shear building, TID ground - floor 1, ground load, top-floor displacement
    M, K = shear_building([2000.0, 2000.0, 1500.0], np.array([1.5, 1.25, 1.0]) * 1e6)
    C = modal_damping(M, K, 0.02)
    w1 = natural_frequencies(M, K)[0][0]
    b = 0.05 * np.trace(M)
    print(f"3-storey: f1 = {w1 / 2 / math.pi:.4f} Hz, b = {b:.1f} kg")
    for kind, floor in (("displacement", 3), ("drift", 1), ("acceleration", 3)):
        peaks = []
        for start in [(b * w1**2, 0.3 * b * w1), (2 * b * w1**2, 0.1 * b * w1),
                      (0.5 * b * w1**2, 1.0 * b * w1)]:
            t0 = time.perf_counter()
            r = h_infinity_search(M, K, C, b=b, spring_floor=1, inerter_floor=0, load="ground",
                                  kind=kind, floor=floor, start=start)
            dt = time.perf_counter() - t0
            peaks.append(r["peak"])
            print(f"  {kind} floor {floor}: k = {r['k']:.10g}, c = {r['c']:.10g}, peak = "
                  f"{r['peak']:.12g}, peaks at {r['frequencies'][0]:.6f}, "
                  f"{r['frequencies'][1]:.6f} rad/s (values rel diff "
                  f"{r['values'][0] / r['values'][1] - 1:.1e}); nfev {r['nfev']}, "
                  f"restarts {r['restarts']}, {dt:.2f} s")
        print(f"  spread of peak over starts: {max(peaks) / min(peaks) - 1:.2e}")


if __name__ == "__main__":
    _demo()
