"""Checks of the independent inerter-device reference against theory (SI units)."""

import math

import numpy as np
import pytest

try:
    from reference.inerter import PAPER_TESTS, device_force, synthetic_records
except ImportError:  # tests/ imported as a package
    from tests.reference.inerter import PAPER_TESTS, device_force, synthetic_records

B, FF, CP, MT = 75.0, 20.0, 50.0, 2.0


def _sine(f, X):
    """u = X sin(2 pi f t) and its two derivatives, as callables of t."""
    w = 2.0 * math.pi * f
    return (lambda t: X * math.sin(w * t), lambda t: X * w * math.cos(w * t),
            lambda t: -X * w * w * math.sin(w * t))


def _rigid(t, f, X, b, ff, cp, mt):
    w = 2.0 * math.pi * f
    return ((b + mt) * (-X * w**2 * np.sin(w * t)) + cp * X * w * np.cos(w * t)
            + ff * np.sign(np.cos(w * t)))


def _away_from_reversals(t, f, margin):
    """Samples farther than ``margin`` [s] from the reversals of X sin(2 pi f t)."""
    half = 0.5 / f
    return np.abs(t % half - 0.5 * half) > margin


def test_rigid_device_is_the_closed_form():
    f, X = 3.0, 0.003
    t = np.arange(2000) / 1000.0
    F = device_force(t, *_sine(f, X), inertance=B, friction_force=FF, parasitic_damping=CP,
                     terminal_mass=MT)
    away = _away_from_reversals(t, f, 1e-3)
    expected = _rigid(t, f, X, B, FF, CP, MT)
    assert np.max(np.abs(F - expected)[away]) <= 1e-12 * np.max(np.abs(expected))


def test_compliant_linear_device_matches_receptance():
    f, X, ks, cp = 4.0, 0.004, 1.2e5, 3000.0  # transient decays as exp(-cp t / 2b) = exp(-20 t)
    t = np.arange(1500) / 1000.0  # 6 periods; the last one (250 samples) is compared
    F = device_force(t, *_sine(f, X), inertance=B, friction_force=0.0, parasitic_damping=cp,
                     series_stiffness=ks, terminal_mass=MT)
    w = 2.0 * math.pi * f
    Z = -B * w**2 + 1j * w * cp
    expected = X * (-MT * w**2 + ks * Z / (ks + Z))  # F = Im(expected exp(i w t))
    last = t >= t[-250]
    basis = np.column_stack((np.sin(w * t[last]), np.cos(w * t[last])))
    (a_sin, a_cos), *_ = np.linalg.lstsq(basis, F[last], rcond=None)
    assert abs(complex(a_sin, a_cos) - expected) <= 1e-6 * abs(expected)
    assert np.max(np.abs(F[last] - basis @ (a_sin, a_cos))) <= 1e-6 * abs(expected)


def test_stiff_series_spring_approaches_rigid_device():
    # The spring-inerter mode (about 1.8 kHz) is excited at the start and by the friction
    # step at the reversal; cp makes it decay as exp(-cp t / 2b) = exp(-50 t).
    f, X, cp = 0.5, 0.02, 7500.0
    t = np.arange(1000) / 1000.0  # half a period, one reversal at 0.5 s
    F = device_force(t, *_sine(f, X), inertance=B, friction_force=FF, parasitic_damping=cp,
                     series_stiffness=1e10)
    expected = _rigid(t, f, X, B, FF, cp, 0.0)
    compared = (t > 0.2) & _away_from_reversals(t, f, 0.2)
    assert np.count_nonzero(compared) > 300
    assert np.max(np.abs(F - expected)[compared]) <= 1e-3 * np.max(np.abs(expected))
    assert 2.0 * FF > 10.0 * 1e-3 * np.max(np.abs(expected))  # friction matters at this level


@pytest.mark.parametrize("mt", [0.0, MT])
def test_backlash_transmits_only_terminal_inertia_in_the_gap(mt):
    f, X, g = 4.0, 4e-3, 1e-3
    t = np.arange(1000) / 1000.0
    u, v, a = _sine(f, X)
    F = device_force(t, u, v, a, inertance=B, friction_force=0.0, parasitic_damping=CP,
                     series_stiffness=1.2e6, backlash=g, terminal_mass=mt)
    spring = F - mt * np.array([a(ti) for ti in t])
    free = np.abs(spring) <= 1e-9 * np.max(np.abs(F))
    assert 20 < np.count_nonzero(free) < t.size
    assert np.all(spring[free] == 0.0)
    # the gap is crossed after each reversal: every half period has free samples
    for k in range(int(2 * f * t[-1])):
        assert np.any(free[(t >= k / (2 * f)) & (t < (k + 1) / (2 * f))])


@pytest.mark.parametrize("g", [0.0, 2e-4])
def test_stuck_mechanism_is_elastic_until_breakaway(g):
    # u = X (1 - cos w t) starts at rest, so the mechanism sticks at q = 0 until
    # ks D(u) reaches ff, which fixes the breakaway time exactly.
    f, X, ks = 1.0, 1e-3, 1.2e5
    w = 2.0 * math.pi * f
    t = np.arange(500) / 1000.0
    F = device_force(t, lambda t: X * (1.0 - math.cos(w * t)), lambda t: X * w * math.sin(w * t),
                     lambda t: X * w * w * math.cos(w * t), inertance=B, friction_force=FF,
                     parasitic_damping=CP, series_stiffness=ks, backlash=g)
    u = X * (1.0 - np.cos(w * t))
    elastic = ks * np.maximum(u - g / 2.0, 0.0)
    t_break = math.acos(1.0 - (FF / ks + g / 2.0) / X) / w
    stuck = t <= t_break
    assert 50 < np.count_nonzero(stuck) < t.size - 50
    assert np.max(np.abs(F - elastic)[stuck]) <= 1e-9 * FF
    assert np.all(F[~stuck] < elastic[~stuck])  # slipping relieves the spring


def test_invalid_inputs_and_event_limit():
    t = np.arange(100) / 1000.0
    motion = _sine(4.0, 4e-3)
    with pytest.raises(ValueError):
        device_force(t, *motion, inertance=B, friction_force=FF, backlash=1e-3)
    with pytest.raises(ValueError):
        device_force(t[::-1], *motion, inertance=B, friction_force=FF)
    with pytest.raises(ValueError):
        device_force(t, *motion, inertance=0.0, friction_force=FF)
    with pytest.raises(RuntimeError, match="events"):
        device_force(np.arange(2000) / 1000.0, *motion, inertance=B, friction_force=FF,
                     series_stiffness=1.2e6, backlash=2e-4, max_events=3)


def test_synthetic_records_paper_device():
    device = dict(inertance=B, friction_force=FF, parasitic_damping=CP, series_stiffness=1.2e6,
                  backlash=2e-4)
    records = synthetic_records(phase=0.2, **device)
    assert len(records) == len(PAPER_TESTS)
    for rec, (f, X, periods) in zip(records, PAPER_TESTS, strict=True):
        n = round(1000.0 * periods / f)
        assert set(rec) == {"time", "displacement", "force"}
        assert all(rec[key].shape == (n,) for key in rec)
        assert np.all(np.isfinite(rec["force"]))
        np.testing.assert_allclose(rec["time"], np.arange(n) / 1000.0, rtol=0, atol=0)
        expected = X * np.sin(2 * math.pi * f * rec["time"] + 0.2)
        np.testing.assert_allclose(rec["displacement"], expected, rtol=0, atol=1e-15)


def test_synthetic_records_noise_and_seed():
    device = dict(inertance=B, friction_force=FF, parasitic_damping=CP, terminal_mass=MT)
    clean = synthetic_records(noise=0.0, **device)
    first = synthetic_records(noise=0.02, seed=7, **device)
    again = synthetic_records(noise=0.02, seed=7, **device)
    other = synthetic_records(noise=0.02, seed=8, **device)
    for c, r1, r2, r3 in zip(clean, first, again, other, strict=True):
        np.testing.assert_array_equal(r1["force"], r2["force"])
        assert not np.array_equal(r1["force"], r3["force"])
        residual = r1["force"] - c["force"]
        sd = 0.02 * np.max(np.abs(c["force"]))
        assert np.std(residual) == pytest.approx(sd, rel=0.1)
        assert abs(np.mean(residual)) < 5.0 * sd / math.sqrt(residual.size)
