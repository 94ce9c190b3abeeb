"""The trust-region SQP method of the robust design, on problems with known solutions."""

from types import SimpleNamespace

import numpy as np
import pytest

from tid_jax._optimise._sqp import Model, minimise_stage, trust_step

Q = np.array([[3.0, 1.0], [1.0, 2.0]])
A = np.array([1.0, -0.5])


def _quadratic(u):
    """f = (u - A) Q (u - A) / 2: its value, gradient and Hessian (rows along u0, u1)."""
    d = u - A
    return Model(float(d @ Q @ d / 2), Q @ d, Q.copy())


def _linear_constraint(b, beta):
    def c(u):
        return Model(float(b @ u - beta), b.copy(), np.zeros((2, 2)))

    return c


def _run(f, c, u0, **options):
    def evaluate(u, accepted):
        del accepted
        return SimpleNamespace(u=u), f(u), None if c is None else c(u), True

    start = SimpleNamespace(u=np.asarray(u0, float))
    settings = dict(max_step=0.25, min_step=1e-12, feasibility=1e-10, max_steps=200, tol=1e-14)
    settings.update(options)
    return minimise_stage(evaluate, start, f(start.u), None if c is None else c(start.u),
                          **settings)


def test_trust_step_is_newton_inside_and_kkt_on_the_boundary():
    g = np.array([0.3, -0.2])
    np.testing.assert_allclose(trust_step(g, Q, 10.0), -np.linalg.solve(Q, g), rtol=1e-12)
    radius = 0.01
    d = trust_step(g, Q, radius)
    assert np.linalg.norm(d) == pytest.approx(radius, rel=1e-9)
    # On the boundary, (Q + lambda I) d = -g with lambda >= 0.
    lam = -(g + Q @ d) @ d / (d @ d)
    assert lam >= 0
    np.testing.assert_allclose((Q + lam * np.eye(2)) @ d, -g, atol=1e-10)
    # Negative curvature: the step goes to the boundary.
    indefinite = np.array([[1.0, 0.0], [0.0, -2.0]])
    assert np.linalg.norm(trust_step(g, indefinite, 0.5)) == pytest.approx(0.5, rel=1e-9)


def test_unconstrained_minimum_of_a_quadratic():
    design, f, c, steps = _run(_quadratic, None, [-2.0, 3.0])
    assert c is None and steps > 1  # the trust radius makes it take several steps
    np.testing.assert_allclose(design.u, A, atol=1e-7)


def test_active_linear_constraint_meets_the_kkt_conditions():
    # min f subject to b.u <= beta, with A outside: u* = A - mu Q^-1 b on b.u = beta.
    b, beta = np.array([1.0, 1.0]), 0.2
    q_inv_b = np.linalg.solve(Q, b)
    mu = (b @ A - beta) / (b @ q_inv_b)
    assert mu > 0
    expected = A - mu * q_inv_b
    design, _, c, _ = _run(_quadratic, _linear_constraint(b, beta), [-1.0, -1.0])
    np.testing.assert_allclose(design.u, expected, atol=1e-7)
    assert abs(c.value) < 1e-9


def test_inactive_constraint_leaves_the_unconstrained_minimum():
    design, _, c, _ = _run(_quadratic, _linear_constraint(np.array([1.0, 1.0]), 5.0),
                           [0.0, 0.0])
    np.testing.assert_allclose(design.u, A, atol=1e-7)
    assert c.value < 0


def test_rosenbrock_from_the_usual_start():
    def rosenbrock(u):
        x, y = u
        value = (1 - x) ** 2 + 100 * (y - x**2) ** 2
        grad = np.array([-2 * (1 - x) - 400 * x * (y - x**2), 200 * (y - x**2)])
        hess = np.array([[2 - 400 * (y - 3 * x**2), -400 * x], [-400 * x, 200.0]])
        return Model(float(value), grad, hess)

    design, _, _, _ = _run(rosenbrock, None, [-1.2, 1.0], max_steps=500)
    np.testing.assert_allclose(design.u, [1.0, 1.0], atol=1e-6)


def test_unusable_trials_are_rejected():
    # Every trial fails (a steady state not found): the start is kept.
    start = SimpleNamespace(u=np.array([-2.0, 3.0]))

    def evaluate(u, accepted):
        return SimpleNamespace(u=u), _quadratic(u), None, False

    design, _, _, steps = minimise_stage(evaluate, start, _quadratic(start.u), None,
                                         max_step=0.25, min_step=1e-6, feasibility=1e-10,
                                         max_steps=100, tol=1e-12)
    assert design is start and 0 < steps < 100


@pytest.mark.parametrize("g, h", [
    ([1.0, 0.0], [[np.nan, 0.0], [0.0, 1.0]]),
    ([np.inf, 0.0], [[1.0, 0.0], [0.0, 1.0]]),
])
def test_trust_step_refuses_a_gradient_or_curvature_that_is_not_finite(g, h):
    # eigh of NaN gives NaN, and the step would be NaN with no word said.
    with pytest.raises(ValueError, match="must be finite"):
        trust_step(np.array(g), np.array(h), 0.5)
