"""Time history of a linear building with a frictionless TID under a ground acceleration
record, by Newmark's average-acceleration method (gamma = 1/2, beta = 1/4, SI units).

The record's acceleration is interpolated linearly between its samples and the method
steps `substeps` times per sample, from rest. The matrices are those of
``building_linear`` (``Mg u'' + Cg u' + Kg u = G a_g(t)``).

Pure numpy; nothing here imports ``tid_jax``.
"""

import numpy as np

try:
    from .building_linear import generalised_load, generalised_matrices
except ImportError:  # run as a script from this folder
    from building_linear import generalised_load, generalised_matrices


def newmark_history(acceleration, dt, M, K, C, *, b, k, c, spring_floor, inerter_floor,
                    cp=0.0, mt=0.0, substeps=20):
    """The coordinates u (floors, then the stroke) and their accelerations u'' at the
    record's samples: arrays (samples, n + 1)."""
    Mg, Cg, Kg = generalised_matrices(M, K, C, b=b, k=k, c=c, spring_floor=spring_floor,
                                      inerter_floor=inerter_floor, cp=cp, mt=mt)
    G = generalised_load(M, load="ground", inerter_floor=inerter_floor, mt=mt)
    h = dt / substeps
    gamma, beta = 0.5, 0.25
    effective = Kg + gamma / (beta * h) * Cg + Mg / (beta * h**2)
    inverse = np.linalg.inv(effective)
    n = Mg.shape[0]
    u, v = np.zeros(n), np.zeros(n)
    a = np.linalg.solve(Mg, G * acceleration[0])
    us, accs = [u.copy()], [a.copy()]
    for i in range(len(acceleration) - 1):
        for s in range(1, substeps + 1):
            ground = acceleration[i] + (acceleration[i + 1] - acceleration[i]) * s / substeps
            load = (G * ground + Mg @ (u / (beta * h**2) + v / (beta * h)
                                       + (0.5 / beta - 1) * a)
                    + Cg @ (gamma / (beta * h) * u + (gamma / beta - 1) * v
                            + h * (0.5 * gamma / beta - 1) * a))
            u_new = inverse @ load
            a_new = (u_new - u) / (beta * h**2) - v / (beta * h) - (0.5 / beta - 1) * a
            v = v + h * ((1 - gamma) * a + gamma * a_new)
            u, a = u_new, a_new
        us.append(u.copy())
        accs.append(a.copy())
    return np.asarray(us), np.asarray(accs)
