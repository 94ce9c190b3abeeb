"""Random family of host + TID systems with friction, for reference studies (SI units).

Each case is a dict with the seven system keys ``host_mass`` M [kg],
``host_stiffness`` K [N/m], ``host_damping`` C [N s/m], ``inertance`` b [kg],
``friction_force`` ff [N], ``tid_stiffness`` k [N/m], ``tid_damping`` c [N s/m], plus
``omega`` [rad/s] and ``amplitude`` A [N] of the forcing ``A sin(omega t)`` on the host.

Sampling (independent draws):

* host frequency fn: log-uniform in [0.1, 10] Hz;
* host mass M: log-uniform in [1e2, 1e7] kg; K = M (2 pi fn)^2;
* mass ratio mu = b / M: log-uniform in [0.005, 0.2];
* host damping ratio zeta: uniform in [0, 0.05]; C = 2 zeta sqrt(K M);
* TID stiffness k: uniform in [0.6, 1.5] x k_DH, damping c: uniform in [0, 2] x c_DH,
  with Den Hartog k_DH = mu K / (1 + mu)^2, c_DH = 2 sqrt(3 mu / (8 (1 + mu))) sqrt(k_DH b);
* forcing frequency omega: uniform in [0.5, 1.6] x 2 pi fn;
* amplitude A: static host displacement A / K log-uniform in [1e-5, 1e-3] m;
* friction force ff: uniform in [0, 0.6] x A (default, ``friction_scale="amplitude"``),
  or uniform in [0, 0.6] x |b omega^2 Y_lin|, the inerter force amplitude of the
  frictionless steady state (``friction_scale="inerter"``; mostly stick-slip and slip,
  whereas the default is mostly stuck for the whole period).

Pure numpy.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["random_system", "family", "den_hartog"]


def den_hartog(host_mass: float, host_stiffness: float, inertance: float) -> tuple[float, float]:
    """Den Hartog TID stiffness [N/m] and damping [N s/m] for a host (M, K) and inertance b."""
    mu = inertance / host_mass
    alpha = 1.0 / (1.0 + mu) ** 2
    xi = math.sqrt(3.0 * mu / (8.0 * (1.0 + mu)))
    k = alpha * mu * host_stiffness
    c = 2.0 * xi * math.sqrt(k * inertance)
    return k, c


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def random_system(rng: np.random.Generator, friction_scale: str = "amplitude") -> dict:
    """One random case of the family (see module docstring); returns a dict of floats."""
    if friction_scale not in ("amplitude", "inerter"):
        raise ValueError(f"friction_scale must be 'amplitude' or 'inerter', got {friction_scale!r}")
    fn = _log_uniform(rng, 0.1, 10.0)
    M = _log_uniform(rng, 1e2, 1e7)
    wn = 2.0 * math.pi * fn
    K = M * wn**2
    mu = _log_uniform(rng, 0.005, 0.2)
    b = mu * M
    zeta = float(rng.uniform(0.0, 0.05))
    C = 2.0 * zeta * math.sqrt(K * M)
    k_dh, c_dh = den_hartog(M, K, b)
    k = float(rng.uniform(0.6, 1.5)) * k_dh
    c = float(rng.uniform(0.0, 2.0)) * c_dh
    omega = float(rng.uniform(0.5, 1.6)) * wn
    A = K * _log_uniform(rng, 1e-5, 1e-3)
    if friction_scale == "amplitude":
        ref = A
    else:
        Z = k + 1j * omega * c
        D = k - b * omega**2 + 1j * omega * c
        X = A / (K - M * omega**2 + 1j * omega * C + Z * (-b * omega**2) / D)
        ref = abs(b * omega**2 * Z * X / D)
    ff = float(rng.uniform(0.0, 0.6)) * ref
    return dict(
        host_mass=M,
        host_stiffness=K,
        host_damping=C,
        inertance=b,
        friction_force=ff,
        tid_stiffness=k,
        tid_damping=c,
        omega=omega,
        amplitude=A,
    )


def family(n: int, seed: int, friction_scale: str = "amplitude") -> list[dict]:
    """``n`` independent cases drawn with ``np.random.default_rng(seed)``."""
    rng = np.random.default_rng(seed)
    return [random_system(rng, friction_scale) for _ in range(int(n))]
