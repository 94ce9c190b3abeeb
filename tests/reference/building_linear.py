"""Frictionless steady state of a multi-storey structure with a tuned inerter damper (TID).

Model, SI units throughout.  A linear structure of ``n`` floors (floors 1..n, floor 0
is the ground) with mass, stiffness and damping matrices ``M``, ``K``, ``C`` (n x n,
displacements ``x`` relative to the ground).  A spring ``k`` [N/m] and a damper ``c``
[N s/m] join floor ``j`` (``spring_floor``, 1..n) to a terminal T; an inerter of
inertance ``b`` [kg] with parasitic viscous damping ``cp`` [N s/m] joins T to floor
``i`` (``inerter_floor``, 0..n, i != j; 0 = the ground).  T carries a point mass ``mt``
[kg].  With the stroke ``r = y - x_i`` (``y`` terminal displacement, ``x_0 = 0``) and
``d = e_j - e_i`` (``e_0 = 0``) the generalised coordinates ``u = (x_1..x_n, r)`` obey
``Mg u'' + Cg u' + Kg u = G a(t)`` with::

    Mg = [[M + mt e_i e_i^T, mt e_i], [mt e_i^T, b + mt]]
    Kg = [[K + k d d^T, -k d], [-k d^T, k]]
    Cg = [[C + c d d^T, -c d], [-c d^T, c + cp]]

A compliant device (``ks`` [N/m] finite) puts a series spring ``ks`` between T and the
inerter's mechanism Q, whose stroke ``q`` (relative to floor ``i``) carries the
inertance, the parasitic damping (and the friction); T keeps ``mt`` (> 0).  Then
``u = (x_1..x_n, r, q)`` and the kinetic energy ``(x'.M x' + mt (x_i' + r')^2 + b q'^2)/2``,
the potential ``(x.K x + k (d.x - r)^2 + ks (r - q)^2)/2`` and the dissipation
``(x'.C x' + c (d.x' - r')^2 + cp q'^2)/2`` give the matrices (``G`` with a last 0).

Loads: ``"force"``: ``a(t) = A sin(w t)``, ``G = [pattern; 0]`` (pattern default: the
top floor only); ``"ground"``: ground acceleration ``a_g = A sin(w t)`` [m/s2],
``G = -[M 1_n + mt e_i; mt]``.

Method: the steady state per unit amplitude is the complex solve
``(-w^2 Mg + i w Cg + Kg) U = G``; responses are moduli of complex amplitudes:
``"displacement"`` ``X_f``, ``"drift"`` ``X_f - X_{f-1}``, ``"acceleration"`` absolute
(``-w^2 X_f + 1`` for ground load, ``-w^2 X_f`` for force load), ``"stroke"`` ``R``.

Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh

__all__ = [
    "complex_amplitudes",
    "generalised_load",
    "generalised_matrices",
    "modal_damping",
    "natural_frequencies",
    "rayleigh_damping",
    "response_amplitude",
    "shear_building",
    "uncontrolled_amplitude",
]


def unit(n, m):
    """Unit vector e_m of length n (floors 1..n); e_0 is the zero vector."""
    e = np.zeros(n)
    if m > 0:
        e[m - 1] = 1.0
    return e


def _check_floors(n, spring_floor, inerter_floor):
    if not 1 <= spring_floor <= n:
        raise ValueError(f"spring_floor must be in 1..{n}, got {spring_floor}")
    if not 0 <= inerter_floor <= n or inerter_floor == spring_floor:
        raise ValueError(f"inerter_floor must be in 0..{n} and != spring_floor")


def generalised_matrices(M, K, C, *, b, k, c, spring_floor, inerter_floor, cp=0.0, mt=0.0,
                         ks=None):
    """(Mg, Cg, Kg) for coordinates (x_1..x_n, r), or (x_1..x_n, r, q) with a series
    stiffness ``ks``."""
    M, K, C = (np.atleast_2d(np.asarray(a, float)) for a in (M, K, C))
    n = M.shape[0]
    _check_floors(n, spring_floor, inerter_floor)
    ei = unit(n, inerter_floor)
    d = unit(n, spring_floor) - ei
    if ks is not None:
        # kinetic energy, potential and dissipation as quadratic forms in (x, r, q)
        N = n + 2
        xi = np.zeros(N)  # x_i + r: the terminal's displacement relative to the ground
        xi[:n], xi[n] = ei, 1.0
        stretch = np.zeros(N)  # d.x - r
        stretch[:n], stretch[n] = d, -1.0
        series = np.zeros(N)  # r - q
        series[n], series[n + 1] = 1.0, -1.0
        Z = np.zeros((N, N))
        Mg, Kg, Cg = Z.copy(), Z.copy(), Z.copy()
        Mg[:n, :n], Kg[:n, :n], Cg[:n, :n] = M, K, C
        Mg += mt * np.outer(xi, xi)
        Mg[n + 1, n + 1] += b
        Kg += k * np.outer(stretch, stretch) + ks * np.outer(series, series)
        Cg += c * np.outer(stretch, stretch)
        Cg[n + 1, n + 1] += cp
        return Mg, Cg, Kg
    Mg = np.block([[M + mt * np.outer(ei, ei), mt * ei[:, None]],
                   [mt * ei[None, :], np.array([[b + mt]])]])
    Kg = np.block([[K + k * np.outer(d, d), -k * d[:, None]],
                   [-k * d[None, :], np.array([[k]])]])
    Cg = np.block([[C + c * np.outer(d, d), -c * d[:, None]],
                   [-c * d[None, :], np.array([[c + cp]])]])
    return Mg, Cg, Kg


def _pattern(n, pattern):
    if pattern is None:
        return unit(n, n)
    p = np.asarray(pattern, float).reshape(-1)
    if p.shape != (n,):
        raise ValueError(f"pattern must have length {n}")
    return p


def generalised_load(M, *, load="force", pattern=None, inerter_floor=0, mt=0.0,
                     compliant=False):
    """Generalised force vector G (length n+1, or n+2 for a compliant device) per unit
    amplitude A."""
    M = np.atleast_2d(np.asarray(M, float))
    n = M.shape[0]
    extra = [0.0] if compliant else []
    if load == "force":
        return np.concatenate([_pattern(n, pattern), [0.0], extra])
    if load == "ground":
        return -np.concatenate([M @ np.ones(n) + mt * unit(n, inerter_floor), [mt], extra])
    raise ValueError(f"load must be 'force' or 'ground', got {load!r}")


def complex_amplitudes(omega, M, K, C, *, b, k, c, spring_floor, inerter_floor, load="force",
                       pattern=None, cp=0.0, mt=0.0, ks=None):
    """Complex amplitudes U (floors 1..n, then stroke r, then a compliant device's q) per
    unit A.

    ``omega`` [rad/s] scalar -> shape (N,); array -> shape omega.shape + (N,).
    """
    Mg, Cg, Kg = generalised_matrices(M, K, C, b=b, k=k, c=c, spring_floor=spring_floor,
                                      inerter_floor=inerter_floor, cp=cp, mt=mt, ks=ks)
    G = generalised_load(M, load=load, pattern=pattern, inerter_floor=inerter_floor, mt=mt,
                         compliant=ks is not None)
    return _solve(omega, Mg, Cg, Kg, G)


def _solve(omega, Mg, Cg, Kg, G):
    w = np.asarray(omega, float)
    ww = w.reshape(-1, 1, 1)
    D = Kg[None] - ww**2 * Mg[None] + 1j * ww * Cg[None]
    U = np.linalg.solve(D, np.broadcast_to(G.astype(complex), (len(ww), len(G)))[..., None])
    return U[..., 0].reshape(w.shape + (len(G),))


def _quantity(omega, U, n, *, load, kind, floor):
    """Complex amplitude of the chosen response from U (last axis: floors then r)."""
    w = np.asarray(omega, float)
    f = n if floor is None else int(floor)
    if kind == "stroke":
        return U[..., n]
    if not 1 <= f <= n:
        raise ValueError(f"floor must be in 1..{n}, got {f}")
    X = U[..., f - 1]
    if kind == "displacement":
        return X
    if kind == "drift":
        return X - U[..., f - 2] if f >= 2 else X
    if kind == "acceleration":
        return -(w**2) * X + (1.0 if load == "ground" else 0.0)
    raise ValueError(f"unknown kind {kind!r}")


def response_amplitude(omega, M, K, C, *, b, k, c, spring_floor, inerter_floor, load="force",
                       pattern=None, kind="displacement", floor=None, cp=0.0, mt=0.0,
                       ks=None):
    """|complex amplitude| of the chosen response per unit A (SI units)."""
    U = complex_amplitudes(omega, M, K, C, b=b, k=k, c=c, spring_floor=spring_floor,
                           inerter_floor=inerter_floor, load=load, pattern=pattern, cp=cp, mt=mt,
                           ks=ks)
    n = np.atleast_2d(M).shape[0]
    return np.abs(_quantity(omega, U, n, load=load, kind=kind, floor=floor))


def uncontrolled_amplitude(omega, M, K, C, *, load="force", pattern=None, kind="displacement",
                           floor=None):
    """|complex amplitude| of the chosen response of the bare structure per unit A."""
    M, K, C = (np.atleast_2d(np.asarray(a, float)) for a in (M, K, C))
    n = M.shape[0]
    if kind == "stroke":
        raise ValueError("the bare structure has no stroke")
    G = generalised_load(M, load=load, pattern=pattern)[:n]
    X = _solve(omega, M, C, K, G)
    return np.abs(_quantity(omega, X, n, load=load, kind=kind, floor=floor))


def shear_building(storey_masses, storey_stiffnesses):
    """(M, K) of a shear building; storey s (between floors s-1 and s) has stiffness k_s."""
    m = np.asarray(storey_masses, float)
    ks = np.asarray(storey_stiffnesses, float)
    n = len(m)
    if ks.shape != (n,):
        raise ValueError("need one stiffness per storey")
    K = np.zeros((n, n))
    for s in range(n):  # storey s+1 joins floor s (index s-1) and floor s+1 (index s)
        K[s, s] += ks[s]
        if s > 0:
            K[s - 1, s - 1] += ks[s]
            K[s, s - 1] -= ks[s]
            K[s - 1, s] -= ks[s]
    return np.diag(m), K


def natural_frequencies(M, K):
    """Undamped natural frequencies [rad/s] (ascending) and mass-normalised modes."""
    lam, Phi = eigh(np.atleast_2d(K), np.atleast_2d(M))
    return np.sqrt(lam), Phi


def modal_damping(M, K, ratio):
    """C = M Phi diag(2 zeta_m w_m) Phi^T M (ratio: scalar or one per mode)."""
    M = np.atleast_2d(np.asarray(M, float))
    w, Phi = natural_frequencies(M, K)
    zeta = np.broadcast_to(np.asarray(ratio, float), w.shape)
    return M @ Phi @ np.diag(2.0 * zeta * w) @ Phi.T @ M


def rayleigh_damping(M, K, ratios, frequencies_hz):
    """a0 M + a1 K with damping ratios (z1, z2) at the frequencies (f1, f2) [Hz]."""
    w = 2.0 * np.pi * np.asarray(frequencies_hz, float)
    A = np.array([[1.0 / (2.0 * w[0]), w[0] / 2.0], [1.0 / (2.0 * w[1]), w[1] / 2.0]])
    a0, a1 = np.linalg.solve(A, np.asarray(ratios, float))
    return a0 * np.asarray(M, float) + a1 * np.asarray(K, float)
