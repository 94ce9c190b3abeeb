from collections.abc import Callable, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._cache import compiled
from ._checks import check_grid, check_optimiser_options, check_system
from ._linear import den_hartog_tuning
from ._peaks import (
    PEAK_NEWTON_STEPS,
    REFINED_PEAKS,
    grid_peak,
    interpolated,
    parabola_vertices,
    smooth_log_peak,
    true_peaks,
)
from ._response import batched, frequency_response, scaled_states
from ._retune import (
    RetuneSettings,
    _band,
    check_retune_options,
    optimal_tunings,
    sweep,
)
from ._sqp import Model, decrement, minimise_stage, stationary, trust_step
from ._steady_state import SolverSettings
from ._system import FIELD_NAMES, PAPER_AMPLITUDES, PAPER_STROKE, TIDSystem

# The parameters that sensitivities are taken with respect to: the physical fields of a
# `TIDSystem` (not the numerical `friction_width`) and the forcing amplitude.
PARAMETERS = FIELD_NAMES[:7] + ("amplitude",)
PARAMETER_UNITS = {
    "host_mass": "kg",
    "host_stiffness": "N/m",
    "host_damping": "N s/m",
    "inertance": "kg",
    "friction_force": "N",
    "tid_stiffness": "N/m",
    "tid_damping": "N s/m",
    "amplitude": "N",
}
_K, _C = PARAMETERS.index("tid_stiffness"), PARAMETERS.index("tid_damping")
# Parameters other than the design (k, c), in the order of the optimiser's coordinates
# (u0, u1, *_OTHER): u0 = ln(k / k_ref), u1 = sqrt(c / c_ref), as in `retune`.
_OTHER = tuple(i for i in range(len(PARAMETERS)) if i not in (_K, _C))

# Design-variable step of the differences of exact gradients that give the curvature of
# each refined peak (forward while optimising, central for the final derivatives; the
# curvature of the smooth maximum across peaks is exact). Smaller steps amplify the noise
# of the orbit solver in the gradients, larger ones the truncation error.
_STENCIL_STEP = 1e-3
_CHUNK = 3  # points per kernel call (one compiled shape for every use)
_MAX_STEP = 0.25  # largest optimiser step in u (about 28% in k)
_MIN_STEP = 1e-8  # trust radius at which a stage gives up
_FEASIBILITY = 1e-6  # |ln(stroke / target)| within which the stroke constraint is met
_POLISH = 3  # Newton steps with central differences before differentiating an optimum
POLISH_TOL = 1e-9  # Newton decrement of the smooth log peak aimed at by the polishing
# The optimiser aims at a Newton decrement below `tol`; the noise of the orbit solver in the
# gradients, and jumps of ~1e-8 in the log peak where a sample's concavity flips, can hold
# it above that (most where peaks of different amplitudes balance). Within
# NOISE_FACTOR * tol (1e-6 of the log peak by default) the optimum counts as converged.
NOISE_FACTOR = 1000.0
_MIN_DAMPING_START = 0.05  # of c_ref, as in `retune`: c = 0 is stationary in u
# The limit is aimed at this fraction below the stated one on the design grid, then checked
# on a grid CHECK_REFINEMENT times finer; if it is exceeded there the design-grid target is
# lowered by the excess and the design polished again (at most _STROKE_ROUNDS times).
STROKE_MARGIN = 0.005
# Sharpness of the smooth worst case over the scenarios of the robust design, in stages:
# its ratios need not balance as finely as the peaks of one optimum
# (`RetuneSettings.sharpness`).
ROBUST_SHARPNESS = (50.0, 1000.0)
CHECK_REFINEMENT = 4
_STROKE_ROUNDS = 3
DAMPING_BOUND_RATIO = 1e-3  # c / c_ref below which c >= 0 is reported as active

ROBUST_STATUS_MESSAGES = {
    0: "ok",
    1: "optimiser did not converge",
    2: "some steady states did not converge",
    3: "stroke over the limit on the check grid",
}


# --- the kernel: refined peaks and their derivatives at a few designs ---------------------


def _log_candidates(values, omegas, true):
    """Log of the parabola-refined value at every grid point of `values` over `omegas`,
    then of the true peaks `true = (index, peaks, valid)` (`_peaks.true_peaks`, in the
    order of their grid indices), and the candidates of the smooth worst case: the
    true peaks, and the other interior local maxima and band ends. The value at every
    sample where the samples are concave is the vertex of the parabola through it and its
    neighbours, clipped to between them (`_peaks.parabola_vertices`). Between nearby
    designs, the same entry holds the same peak (the true peaks in the order of
    frequency, wherever the grid falls), so that differences of its gradient give its
    curvature."""
    index, peaks, valid = true
    vertex, _, is_peak = parabola_vertices(values, omegas)
    true_mask = jnp.ones(1, dtype=bool)
    grid_mask = jnp.concatenate([true_mask, is_peak, true_mask]).at[index].set(False)
    logs = jnp.log(jnp.concatenate([values[:1], vertex, values[-1:], peaks]))
    return logs, jnp.concatenate([grid_mask, valid])


def _changed_system(system, theta, scale):
    """`system` with the parameters `theta` (order `PARAMETERS`, amplitude last and unused)
    and its host stiffness multiplied by `scale**2`."""
    mass, stiffness, damping, inertance, friction, k, c, _ = theta
    return eqx.tree_at(
        lambda s: (
            s.host_mass,
            s.host_stiffness,
            s.host_damping,
            s.inertance,
            s.friction_force,
            s.tid_stiffness,
            s.tid_damping,
        ),
        system,
        (mass, stiffness * scale**2, damping, inertance, friction, k, c),
    )


def _point_curves(system, theta, scale, omegas, settings, z_init, locate):
    """Log refined peaks of |x| and |y| (m) over `omegas`, with the true peaks of |x| if
    `locate` (see `_log_candidates`), for the parameters `theta` (order `PARAMETERS`),
    with the host stiffness multiplied by `scale**2`."""
    changed = _changed_system(system, theta, scale)
    xs, ys, converged, states = sweep(changed, theta[-1], omegas, settings, z_init)
    states = jax.lax.stop_gradient(states)

    def located(values):
        def solve(step, at):
            # Only the peak (the response at the last Newton iterate) is differentiated.
            t = theta if step == PEAK_NEWTON_STEPS else jax.lax.stop_gradient(theta)
            x, _, ok, _ = jax.vmap(sweep, (None, None, 0, None, 0))(
                _changed_system(system, t, scale), t[-1], at, settings,
                interpolated(states, omegas, at))
            return jnp.where(ok, x, jnp.nan)

        selection = jnp.where(converged, jax.lax.stop_gradient(values), 0.0)
        index, peaks, _, valid = true_peaks(selection, omegas, solve, REFINED_PEAKS)
        order = jnp.argsort(index)
        return index[order], peaks[order], valid[order]

    # The host's peaks are located in continuous frequency, the stroke's are the grid's
    # (see `_retune.response_peaks`).
    none = (jnp.zeros(0, int), jnp.zeros(0, ys.dtype), jnp.zeros(0, bool))
    true_x = located(xs) if locate else none
    converged = jnp.concatenate([converged, jnp.isfinite(true_x[1]) | ~true_x[2]])
    log_x, peak_x = _log_candidates(xs, omegas, true_x)
    log_y, peak_y = _log_candidates(ys, omegas, none)
    return (log_x, log_y), (log_x, log_y, peak_x, peak_y, converged, states, true_x[0])


@compiled
def _evaluate_points(system, thetas, scales, ratio_grid, settings, z_init, locate):
    """`_CHUNK` points at once, shooting from the scaled states `z_init`: for each, the log
    refined peaks (with the host's true peaks if `locate`), candidate masks and their
    Jacobians with respect to `theta` (forward mode, implicit differentiation through the
    orbits). Each point's band is `ratio_grid` times its host frequency."""
    host_frequency = jax.lax.stop_gradient(system.host_frequency)

    def one(theta, scale, z0):
        omegas = ratio_grid * host_frequency * scale

        def curves(t):
            return _point_curves(system, t, scale, omegas, settings, z0, locate)

        return jax.jacfwd(curves, has_aux=True)(theta)

    return jax.vmap(one)(thetas, scales, jax.lax.stop_gradient(z_init))


# --- host side: points, stencils, the smooth worst case and its derivatives ----------------


class _Curves(NamedTuple):
    """One design point (numpy): log refined values (ln m) of |x| and |y| per frequency
    (then the true peaks of |x|, if located), their candidate masks (`_log_candidates`),
    Jacobians `[entries, PARAMETERS]`, convergence of every orbit, the orbits' states and
    the grid indices of the true peaks."""

    log_x: np.ndarray
    log_y: np.ndarray
    peak_x: np.ndarray
    peak_y: np.ndarray
    jac_x: np.ndarray
    jac_y: np.ndarray
    converged: bool
    states: np.ndarray
    located: np.ndarray

    def top(self, response: str) -> tuple[float, np.ndarray]:
        """Log of the grid peak of `response` ("x" or "y"), as `_peaks.grid_peak` finds it,
        and its gradient (`PARAMETERS`)."""
        values = np.where(
            getattr(self, f"peak_{response}"), getattr(self, f"log_{response}"), -np.inf
        )
        i = int(np.argmax(values))
        return float(values[i]), getattr(self, f"jac_{response}")[i]

    def host_peak(self) -> float:
        return float(np.exp(self.top("x")[0]))

    def stroke_peak(self) -> float:
        return float(np.exp(self.top("y")[0]))


class _Context:
    """What every evaluation shares: the system, the band as multiples of the host
    frequency, the solver settings, whether the host's peaks are located in continuous
    frequency (`locate`: as `retune` does, for the sensitivities of its optimum; else
    the grid's, refined by parabolas) and the reference tuning of the design variables
    u = (ln(k / k_ref), sqrt(c / c_ref))."""

    def __init__(self, system: TIDSystem, omegas, settings: SolverSettings, *, locate: bool):
        self.system = system
        self.locate = locate
        self.settings = settings
        self.omegas = np.asarray(omegas, dtype=float)
        self.ratio_grid = jnp.asarray(self.omegas / float(system.host_frequency))
        self.values = np.array([float(getattr(system, name)) for name in PARAMETERS[:-1]])
        k_ref, c_ref = den_hartog_tuning(system.host_mass, system.host_stiffness, system.inertance)
        self.k_ref, self.c_ref = float(k_ref), float(c_ref)

    def tuning(self, u) -> tuple[float, float]:
        return self.k_ref * float(np.exp(u[0])), self.c_ref * float(u[1]) ** 2

    def design(self, k, c, *, floor=0.0) -> np.ndarray:
        return np.array([np.log(k / self.k_ref), np.sqrt(max(c / self.c_ref, floor))])

    def theta(self, k, c, amplitude) -> np.ndarray:
        theta = np.append(self.values, float(amplitude))
        theta[_K], theta[_C] = k, c
        return theta

    def evaluate(self, points: Sequence[tuple]) -> list[_Curves]:
        """`_Curves` at each `(theta, scale, z_init)`; points where a steady state did not
        converge are tried again with each of `SolverSettings.fallbacks()` in turn."""
        results = self._evaluate(points, self.settings)
        for settings in self.settings.fallbacks():
            failed = [i for i, curves in enumerate(results) if not curves.converged]
            if not failed:
                break
            retried = self._evaluate([points[i] for i in failed], settings)
            for i, curves in zip(failed, retried, strict=True):
                if curves.converged:
                    results[i] = curves
        return results

    def _evaluate(self, points: Sequence[tuple], settings: SolverSettings) -> list[_Curves]:
        """`_Curves` at each point with `settings`, `_CHUNK` points per compiled call."""
        results = []
        for start in range(0, len(points), _CHUNK):
            chunk = list(points[start : start + _CHUNK])
            used = len(chunk)
            chunk += [chunk[-1]] * (_CHUNK - used)
            thetas, scales, z_init = (np.stack([point[i] for point in chunk]) for i in range(3))
            (jac_x, jac_y), aux = _evaluate_points(
                self.system,
                jnp.asarray(thetas),
                jnp.asarray(scales, dtype=float),
                self.ratio_grid,
                settings,
                jnp.asarray(z_init),
                self.locate,
            )
            jac_x, jac_y = np.asarray(jac_x), np.asarray(jac_y)
            aux = [np.asarray(a) for a in aux]
            for i in range(used):
                log_x, log_y, peak_x, peak_y, converged, states, located = (
                    a[i] for a in aux
                )
                results.append(
                    _Curves(
                        log_x,
                        log_y,
                        peak_x,
                        peak_y,
                        jac_x[i],
                        jac_y[i],
                        bool(np.all(converged)),
                        states,
                        located,
                    )
                )
        return results

    def cold_states(self, k, c, amplitudes, scale) -> np.ndarray:
        """Scaled orbit states `[amps, freqs, 4]` at the tuning (k, c) for each amplitude,
        from `frequency_response` (which retries points that fail to converge)."""
        changed = self.system.replace(
            host_stiffness=float(self.system.host_stiffness) * scale**2,
            tid_stiffness=k,
            tid_damping=c,
        )
        omegas = self.omegas * scale
        amplitudes = np.atleast_1d(np.asarray(amplitudes, dtype=float))
        response = frequency_response(changed, omegas, amplitudes, settings=self.settings)
        return np.asarray(scaled_states(response, float(changed.host_stiffness)))


class _Scenario(NamedTuple):
    amplitude: float  # N
    scale: float  # host frequency / nominal host frequency
    offset: float  # subtracted from the log host peak: ln of the best achievable peak, or 0


def _stencil(u, central: bool) -> list[np.ndarray]:
    h = _STENCIL_STEP
    steps = [[h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]] if central else [[h, 0.0], [0.0, h]]
    return [np.asarray(u, dtype=float)] + [u + np.asarray(step) for step in steps]


def _coordinates(ctx: _Context, u, stencil: list[_Curves], response: str):
    """Log peaks, their gradients in the coordinates (u0, u1, parameters `_OTHER`) and
    the derivatives of those gradients along u0 and u1, for every frequency of one
    scenario, from the curves at the designs `_stencil(u, central)` (central when there
    are five). Only the second derivatives of each refined peak come from differences."""
    k, _ = ctx.tuning(u)
    jac = [getattr(curves, f"jac_{response}") for curves in stencil]
    centre = jac[0]
    grad = np.concatenate(
        [k * centre[:, [_K]], 2 * ctx.c_ref * u[1] * centre[:, [_C]], centre[:, _OTHER]], axis=1
    )
    dgrad = np.empty(grad.shape[:1] + (2,) + grad.shape[1:])
    for i in range(2):
        if len(stencil) == 5:
            d_jac = (jac[1 + 2 * i] - jac[2 + 2 * i]) / (2 * _STENCIL_STEP)
        else:
            d_jac = (jac[1 + i] - centre) / _STENCIL_STEP
        dgrad[:, i, 0] = k * d_jac[:, _K] + (k * centre[:, _K] if i == 0 else 0.0)
        dgrad[:, i, 1] = 2 * ctx.c_ref * (u[1] * d_jac[:, _C] + (centre[:, _C] if i == 1 else 0.0))
        dgrad[:, i, 2:] = d_jac[:, _OTHER]
    if response == "x" and stencil[0].located.size:
        # A true peak's entry holds the same peak at every design of the stencil unless the
        # set of highest local maxima changed between them (its grid index jumps): then
        # its curvature is unknown and left out.
        located = np.stack([curves.located for curves in stencil])
        changed = np.any(np.abs(located - located[0]) > 1, axis=0)
        dgrad[dgrad.shape[0] - changed.size:][changed] = 0.0
    curves = stencil[0]
    values = getattr(curves, f"log_{response}")
    return values, getattr(curves, f"peak_{response}"), grad, dgrad


def _smooth_max(values, mask, grad, dgrad, sharpness):
    """Smooth maximum G = ln(sum exp(s T)) / s of the candidate terms T, its gradient in
    all coordinates and its derivatives along u0, u1 (rows) in all coordinates: the exact
    curvature of the log-sum-exp plus the weighted curvatures of the terms."""
    terms = np.where(mask, values, -np.inf)
    top = np.max(terms)
    if not np.isfinite(top):
        return np.inf, None, None
    weights = np.exp(sharpness * (terms - top))
    total = weights.sum()
    weights /= total
    grad = np.where(mask[:, None], grad, 0.0)
    dgrad = np.where(mask[:, None, None], dgrad, 0.0)
    g = weights @ grad
    hess = sharpness * (np.einsum("n,ni,nj->ij", weights, grad[:, :2], grad) - np.outer(g[:2], g))
    hess += np.einsum("n,nij->ij", weights, dgrad)
    return top + np.log(total) / sharpness, g, hess


class _Evaluation(NamedTuple):
    u: np.ndarray
    stencils: list  # per scenario, the curves at `_stencil(u, central)`
    host_terms: tuple  # (values, mask, grad, dgrad), all scenarios' terms concatenated
    stroke_terms: tuple

    def centres(self) -> list[_Curves]:
        return [stencil[0] for stencil in self.stencils]

    def converged(self) -> bool:
        return all(curves.converged for curves in self.centres())


def _evaluate_design(ctx, u, scenarios, z_inits, *, central=False) -> _Evaluation:
    """Curves at the design u and its stencil for every scenario (shooting from `z_inits`,
    one state array per scenario), and the terms of the smooth maxima: each scenario's log
    host peaks less its offset, and its log inerter peaks."""
    designs = _stencil(u, central)
    points = []
    for scenario, z in zip(scenarios, z_inits, strict=True):
        points += [
            (ctx.theta(*ctx.tuning(v), scenario.amplitude), scenario.scale, z) for v in designs
        ]
    curves = ctx.evaluate(points)
    n = len(designs)
    stencils = [curves[i : i + n] for i in range(0, len(curves), n)]
    host, stroke = [], []
    for scenario, stencil in zip(scenarios, stencils, strict=True):
        values, mask, grad, dgrad = _coordinates(ctx, designs[0], stencil, "x")
        host.append((values - scenario.offset, mask, grad, dgrad))
        stroke.append(_coordinates(ctx, designs[0], stencil, "y"))

    def join(parts):
        return tuple(np.concatenate([part[i] for part in parts]) for i in range(4))

    return _Evaluation(designs[0], stencils, join(host), join(stroke))


def _cold_start(ctx: _Context, u, scenarios) -> list[np.ndarray]:
    """Orbit states at the design u for every scenario, one `frequency_response` call per
    host-frequency scale."""
    states = [None] * len(scenarios)
    for scale in sorted({scenario.scale for scenario in scenarios}):
        index = [i for i, scenario in enumerate(scenarios) if scenario.scale == scale]
        amplitudes = [scenarios[i].amplitude for i in index]
        for i, z in zip(index, ctx.cold_states(*ctx.tuning(u), amplitudes, scale), strict=True):
            states[i] = z
    return states


class _Minimum(NamedTuple):
    evaluation: _Evaluation
    objective: "Model"  # the smooth worst case at the last stage's sharpness
    constraint: "Model | None"  # the stroke constraint, if any
    steps: int
    converged: bool


def _models(evaluation: _Evaluation, sharpness, stroke_log_limit):
    """The worst case f (smooth maximum of the host terms) and, if a stroke limit is given,
    the constraint c = (smooth maximum of the log inerter peaks) - ln(limit) <= 0."""
    f = Model(*_smooth_max(*evaluation.host_terms, sharpness))
    if stroke_log_limit is None:
        return f, None
    value, grad, hess = _smooth_max(*evaluation.stroke_terms, sharpness)
    return f, Model(value - stroke_log_limit, grad, hess)


def _minimise(
    ctx,
    scenarios,
    u,
    *,
    stroke_log_limit=None,
    z_inits=None,
    stages=ROBUST_SHARPNESS,
    max_steps,
    tol,
    say=None,
) -> _Minimum:
    """Minimise the smooth worst case f over `scenarios` in the design variables u, at each
    smooth-max sharpness of `stages` in turn, by a trust-region Newton method; with a
    stroke limit, by sequential quadratic programming on the constraint c <= 0 with the
    exact penalty f + weight max(c, 0) as merit function."""
    if z_inits is None:
        z_inits = _cold_start(ctx, u, scenarios)
    current = _evaluate_design(ctx, np.asarray(u, dtype=float), scenarios, z_inits)
    steps, converged = 0, False
    for stage, sharpness in enumerate(stages, start=1):
        f, c = _models(current, sharpness, stroke_log_limit)
        if not np.isfinite(f.value) or (c is not None and not np.isfinite(c.value)):
            return _Minimum(current, f, c, steps, False)

        def evaluate(u, accepted, sharpness=sharpness):
            trial = _evaluate_design(
                ctx, u, scenarios, [curves.states for curves in accepted.centres()])
            t_f, t_c = _models(trial, sharpness, stroke_log_limit)
            return trial, t_f, t_c, trial.converged()

        current, f, c, stage_steps = minimise_stage(
            evaluate, current, f, c, max_step=_MAX_STEP, min_step=_MIN_STEP,
            feasibility=_FEASIBILITY, max_steps=max_steps, tol=tol)
        steps += stage_steps
        converged = stationary(f, c, NOISE_FACTOR * tol, _FEASIBILITY)
        if say is not None:
            k, c_tuned = ctx.tuning(current.u)
            say(
                f"stage {stage}/{len(stages)} (smooth-max sharpness {sharpness:g}): "
                f"{steps} steps, k = {k:.6g} N/m, c = {c_tuned:.5g} N s/m"
                + ("" if converged else ", not converged")
            )
    return _Minimum(current, f, c, steps, converged)


# --- checks of user input ------------------------------------------------------------------


def _check_amplitude(amplitude) -> float:
    if isinstance(amplitude, jax.core.Tracer):
        raise ValueError("amplitude must be concrete (not traced)")
    array = check_grid("amplitude", amplitude)
    if array.ndim != 0:
        raise ValueError(f"amplitude must be a scalar, got shape {array.shape}")
    return float(array)


def _check_amplitudes(amplitudes) -> np.ndarray:
    array = np.atleast_1d(check_grid("amplitudes", amplitudes))
    if np.unique(array).size != array.size:
        raise ValueError(f"amplitudes must be distinct, got {array.tolist()}")
    return array


def _check_scales(scales) -> np.ndarray:
    array = np.atleast_1d(check_grid("host_frequency_scales", scales))
    if np.unique(array).size != array.size:
        raise ValueError(f"host_frequency_scales must be distinct, got {array.tolist()}")
    return array


# --- sensitivities -------------------------------------------------------------------------


class OptimumSensitivities(eqx.Module):
    """How the retuned optimum moves with each parameter. The optimum is the tuning
    (k*, c*) minimising the smooth maximum over the band of the host displacement (see
    `best_tunings`), solved to stationarity. Arrays are ordered as
    `Sensitivities.parameters`; their `tid_stiffness` and `tid_damping` entries are 0, as
    the optimum does not depend on the tuning it starts from. SI units.

    - `tid_stiffness` (N/m), `tid_damping` (N s/m): k*, c*.
    - `host_peak`, `stroke_peak`: peak |x| and |y| over the band at the optimum, m.
    - `smooth_peak`: the smooth maximum over the band of |x| that the optimum minimises
      (a few tenths of a percent above `host_peak`), m.
    - `host_elasticity`: d ln peak* / d ln p of the optimal host peak: of `smooth_peak`
      exactly, by the envelope theorem (the partial derivative at fixed k*, c*);
      `host_derivative = host_peak * host_elasticity / p`, m per unit of p.
    - `stroke_derivative`, `stroke_elasticity`: of the inerter peak at the optimum, as the
      optimum moves (partial derivative plus the change through k* and c*).
    - `stiffness_derivative`, `stiffness_elasticity`, `damping_derivative`,
      `damping_elasticity`: dk*/dp, dc*/dp (units of k or c per unit of p) and their
      elasticities, by implicit differentiation of the stationarity condition (elasticities
      of c* are 0 when c* is at its bound 0).
    - `gradient_norm`: |dG/du| at the optimum, G the smooth log peak and u the design
      variables (ln k, sqrt c); `iterations`: Newton steps; `converged`: a stationary point
      was found and every steady state converged; `damping_at_bound`: c* = 0.
    """

    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    host_peak: Float[Array, ""]
    stroke_peak: Float[Array, ""]
    smooth_peak: Float[Array, ""]
    host_derivative: Float[Array, " params"]
    host_elasticity: Float[Array, " params"]
    stroke_derivative: Float[Array, " params"]
    stroke_elasticity: Float[Array, " params"]
    stiffness_derivative: Float[Array, " params"]
    stiffness_elasticity: Float[Array, " params"]
    damping_derivative: Float[Array, " params"]
    damping_elasticity: Float[Array, " params"]
    gradient_norm: Float[Array, ""]
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    damping_at_bound: Bool[Array, ""]


class Sensitivities(eqx.Module):
    """Derivatives of the peak host displacement and of the inerter stroke over the band with
    respect to each parameter in `parameters` (the physical fields of `TIDSystem` and the
    forcing `amplitude`; their units in `PARAMETER_UNITS`), at the given tuning and, in
    `optimum` (None if not asked for), at the retuned optimum. SI units.

    - `values`: the parameters' values.
    - `host_peak`, `stroke_peak`: peak |x| and |y| over the band, m.
    - `host_derivative`, `stroke_derivative`: d peak / dp, m per unit of p.
    - `host_elasticity`, `stroke_elasticity`: d ln peak / d ln p = (p / peak) d peak / dp.
    - `converged`: every steady state in the band converged.

    `as_dict()` gives the same numbers keyed by parameter name.
    """

    parameters: tuple[str, ...] = eqx.field(static=True)
    values: Float[Array, " params"]
    host_peak: Float[Array, ""]
    stroke_peak: Float[Array, ""]
    host_derivative: Float[Array, " params"]
    host_elasticity: Float[Array, " params"]
    stroke_derivative: Float[Array, " params"]
    stroke_elasticity: Float[Array, " params"]
    converged: Bool[Array, ""]
    optimum: OptimumSensitivities | None

    def as_dict(self) -> dict[str, dict[str, float]]:
        """`{parameter: {quantity: value}}` with the per-parameter arrays of this result
        and, prefixed `optimum_`, of `optimum`."""
        arrays = {
            name: getattr(self, name)
            for name in (
                "values",
                "host_derivative",
                "host_elasticity",
                "stroke_derivative",
                "stroke_elasticity",
            )
        }
        if self.optimum is not None:
            for name in (
                "host_derivative",
                "host_elasticity",
                "stroke_derivative",
                "stroke_elasticity",
                "stiffness_derivative",
                "stiffness_elasticity",
                "damping_derivative",
                "damping_elasticity",
            ):
                arrays[f"optimum_{name}"] = getattr(self.optimum, name)
        return {
            parameter: {key: float(array[i]) for key, array in arrays.items()}
            for i, parameter in enumerate(self.parameters)
        }


def _polished(ctx, scenario, u, z_init, at_bound, tol, sharpness):
    """The evaluation (central stencil) at the optimum of the smooth log peak of `retune`
    (of its last stage's `sharpness`) near u, its smooth maximum, gradient and
    derivatives: at most `_POLISH` Newton steps from u (along u0 alone, with u1 = 0,
    where the damping is at its bound)."""
    final = _evaluate_design(ctx, u, [scenario], [z_init], central=True)
    model = Model(*_smooth_max(*final.host_terms, sharpness))
    free = slice(0, 1) if at_bound else slice(0, 2)
    for _ in range(_POLISH):
        g, h = model.grad[free], model.curvature()[free, free]
        if decrement(g, h) < tol:
            break
        step = np.zeros(2)
        step[free] = trust_step(g, h, _MAX_STEP)
        trial = _evaluate_design(ctx, final.u + step, [scenario],
                                 [curves.states for curves in final.centres()], central=True)
        trial_model = Model(*_smooth_max(*trial.host_terms, sharpness))
        if not trial_model.value < model.value:
            break
        final, model = trial, trial_model
    return final, model


def _optimum_sensitivities(ctx, scenario, theta, best: "BestTunings", index, tol, sharpness):
    """`OptimumSensitivities` at the best tuning `best[index]`, polished (see `_polished`)
    and differentiated through its stationarity condition: in (u0, u1), or where the
    damping is at its bound, in u0 alone with dc*/dp = 0 (the bound stays active)."""
    at_bound = bool(best.damping_at_bound[index])
    k, c = float(best.tid_stiffness[index]), float(best.tid_damping[index])
    u = ctx.design(k, 0.0 if at_bound else c)
    z_init = ctx.cold_states(k, c, [scenario.amplitude], scenario.scale)[0]
    final, model = _polished(ctx, scenario, u, z_init, at_bound, tol, sharpness)
    u = final.u
    k, c = ctx.tuning(u)
    g, h_uu = model.grad, model.curvature()
    free = [0] if at_bound else [0, 1]
    du_dp = np.zeros((2, len(_OTHER)))
    du_dp[free] = -np.linalg.solve(h_uu[np.ix_(free, free)], model.hess[free, 2:])
    centre = final.centres()[0]
    values, _, stroke_grads, _ = _coordinates(ctx, u, final.stencils[0], "y")
    stroke_grad = stroke_grads[int(np.argmax(np.where(centre.peak_y, values, -np.inf)))]
    n = len(PARAMETERS)
    d_log_host, d_log_stroke, dk, dc = (np.zeros(n) for _ in range(4))
    # Envelope theorem, with the first-order effect of the gradient left at the optimum
    # (the smooth maximum is stiff across a balance of peaks: a small step there leaves a
    # gradient that is not negligible against the partial derivative).
    d_log_host[list(_OTHER)] = g[2:] + g[:2] @ du_dp
    d_log_stroke[list(_OTHER)] = stroke_grad[2:] + stroke_grad[:2] @ du_dp
    dk[list(_OTHER)] = k * du_dp[0]
    dc[list(_OTHER)] = 2 * ctx.c_ref * u[1] * du_dp[1]
    host_peak, stroke_peak = centre.host_peak(), centre.stroke_peak()
    at_optimum = decrement(g[free], h_uu[np.ix_(free, free)]) < NOISE_FACTOR * tol
    # At the bound the peak must rise with the damping (a positive curvature in u1).
    at_optimum &= not at_bound or h_uu[1, 1] > 0
    return OptimumSensitivities(
        tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c),
        host_peak=jnp.asarray(host_peak),
        stroke_peak=jnp.asarray(stroke_peak),
        smooth_peak=jnp.asarray(float(np.exp(model.value))),
        host_derivative=jnp.asarray(host_peak * d_log_host),
        host_elasticity=jnp.asarray(theta * d_log_host),
        stroke_derivative=jnp.asarray(stroke_peak * d_log_stroke),
        stroke_elasticity=jnp.asarray(theta * d_log_stroke),
        stiffness_derivative=jnp.asarray(dk),
        stiffness_elasticity=jnp.asarray(theta * dk / k),
        damping_derivative=jnp.asarray(dc),
        # The elasticity of a quantity held at zero is undefined.
        damping_elasticity=jnp.asarray(np.full(n, np.nan) if at_bound else theta * dc / c),
        gradient_norm=jnp.asarray(float(np.linalg.norm(g[free]))),
        iterations=jnp.asarray(int(best.iterations[index])),
        converged=jnp.asarray(bool(at_optimum and final.converged()
                                   and best.converged[index])),
        damping_at_bound=jnp.asarray(at_bound),
    )


def _best_index(best: "BestTunings", system, band, amplitude) -> tuple[int, int]:
    """Where `best` holds the nominal scenario at `amplitude`, else `ValueError`."""
    _check_best(best, system)
    if best.omegas.shape != band.shape or not np.allclose(best.omegas, band, rtol=1e-12):
        raise ValueError("omegas differ from the band best was computed on")
    scales, amps = np.asarray(best.host_frequency_scales), np.asarray(best.amplitudes)
    i, j = np.flatnonzero(np.isclose(scales, 1.0, rtol=1e-12)), np.flatnonzero(
        np.isclose(amps, amplitude, rtol=1e-12))
    if not (i.size and j.size):
        raise ValueError(f"best holds no tuning for {amplitude:g} N at the nominal host "
                         f"frequency (amplitudes {amps.tolist()}, scales {scales.tolist()})")
    return int(i[0]), int(j[0])


def sensitivities(
    system: TIDSystem,
    amplitude: ArrayLike,
    *,
    omegas: ArrayLike | None = None,
    optimum: bool = True,
    best: "BestTunings | None" = None,
    settings: SolverSettings = SolverSettings(),
    max_steps: int = 60,
    tol: float = 1e-4,
    retune_settings: RetuneSettings = RetuneSettings(),
) -> Sensitivities:
    """Sensitivities of the peak steady-state host displacement and inerter stroke over the
    band `omegas` (rad/s; default `default_omegas(system)`) at forcing amplitude `amplitude`
    (N) to every physical parameter and the amplitude: derivatives and elasticities, by
    forward-mode implicit differentiation through the periodic orbits.

    With `optimum=True` also at the retuned optimum (see `OptimumSensitivities`): the
    tuning that `retune` finds (from `best`, a `BestTunings` of this system and band
    holding `amplitude`, or else from `best_tunings` with `max_steps`, `tol` and
    `retune_settings`), polished by at most `_POLISH` Newton steps on the same objective
    (the smooth maximum of `retune_settings.sharpness[-1]`, aiming at a Newton decrement
    below `POLISH_TOL`, converged within `NOISE_FACTOR * POLISH_TOL`), then differentiated
    through its stationarity condition rather than re-optimised. Where the optimal damping
    is at its bound 0, only k* moves: dc*/dp = 0 and the elasticities of c* are NaN.
    """
    check_system(system)
    amplitude = _check_amplitude(amplitude)
    band = _band(system, omegas)
    if not isinstance(optimum, bool):
        raise ValueError(f"optimum must be True or False, got {optimum!r}")
    check_retune_options(max_steps, tol, retune_settings)
    ctx = _Context(system, band, settings, locate=True)
    scenario = _Scenario(amplitude, 1.0, 0.0)
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    theta = ctx.theta(k, c, amplitude)
    z_given = ctx.cold_states(k, c, [amplitude], 1.0)[0]
    given = ctx.evaluate([(theta, 1.0, z_given)])[0]
    log_host, d_log_host = given.top("x")
    log_stroke, d_log_stroke = given.top("y")
    optimal = None
    if optimum:
        if best is None:
            best = best_tunings(system, [amplitude], omegas=band, settings=settings,
                                max_steps=max_steps, tol=tol, retune_settings=retune_settings)
        index = _best_index(best, system, band, amplitude)
        optimal = _optimum_sensitivities(ctx, scenario, theta, best, index, POLISH_TOL,
                                         retune_settings.sharpness[-1])
    host_peak, stroke_peak = np.exp(log_host), np.exp(log_stroke)
    return Sensitivities(
        parameters=PARAMETERS,
        values=jnp.asarray(theta),
        host_peak=jnp.asarray(host_peak),
        stroke_peak=jnp.asarray(stroke_peak),
        host_derivative=jnp.asarray(host_peak * d_log_host),
        host_elasticity=jnp.asarray(theta * d_log_host),
        stroke_derivative=jnp.asarray(stroke_peak * d_log_stroke),
        stroke_elasticity=jnp.asarray(theta * d_log_stroke),
        converged=jnp.asarray(given.converged),
        optimum=optimal,
    )


# --- the best tuning per scenario, any tuning against it, the robust tuning ---------------


class BestTunings(eqx.Module):
    """For each host-frequency scale and forcing amplitude, the retuned optimum: the tuning
    that `retune` finds (the minimiser of the smooth maximum over the band of the host
    displacement), and the peaks it achieves. Arrays are `[scales, amps]`; SI.

    - `system`: the nominal system; a scale s multiplies its host stiffness by s**2 (host
      frequency by s) and its band `omegas` (rad/s) by s.
    - `tid_stiffness` (N/m), `tid_damping` (N s/m): the best tuning.
    - `host_peak`: peak |x| over the band's grid with it (refined by a parabola, as the
      robust design judges peaks), m; `stroke_peak`: peak |y|, m, on the check grid of
      `retune` (`RetuneSettings.check_refinement` times finer than the band).
    - `objective`: the smooth log peak over the band's grid (`smooth_log_peak`, sharpness
      `ROBUST_SHARPNESS[-1]`, ln m), the reference of the worst-case ratio of
      `robust_tune`.
    - `iterations`: optimiser iterations; `stationary`: the optimiser converged;
      `converged`: `retune`'s status is ok (stationary, every steady state converged, the
      peak inside the band and no higher than the starting tuning's on the check grid);
      `damping_at_bound`: c = 0 is optimal.
    """

    system: TIDSystem
    omegas: Float[Array, " freqs"]
    amplitudes: Float[Array, " amps"]
    host_frequency_scales: Float[Array, " scales"]
    tid_stiffness: Float[Array, "scales amps"]
    tid_damping: Float[Array, "scales amps"]
    host_peak: Float[Array, "scales amps"]
    stroke_peak: Float[Array, "scales amps"]
    objective: Float[Array, "scales amps"]
    iterations: Int[Array, "scales amps"]
    stationary: Bool[Array, "scales amps"]
    converged: Bool[Array, "scales amps"]
    damping_at_bound: Bool[Array, "scales amps"]


def _scaled_lanes(system: TIDSystem, scales) -> TIDSystem:
    """One system per scale s (batched fields): host stiffness times s**2 and, keeping the
    TID's frequency ratio and damping ratio (Den Hartog's k scales with K and c with
    sqrt(k b)), TID stiffness times s**2 and damping times s."""
    scales = jnp.asarray(scales, float)
    lanes = batched(system, scales.size)
    return eqx.tree_at(
        lambda s: (s.host_stiffness, s.tid_stiffness, s.tid_damping),
        lanes,
        (lanes.host_stiffness * scales**2, lanes.tid_stiffness * scales**2,
         lanes.tid_damping * scales),
    )


def _smooth_objective(values, omegas) -> np.ndarray:
    """`BestTunings.objective` from the host peaks `values` (m, lanes x frequencies)."""
    smooth = jax.vmap(lambda v, w: smooth_log_peak(v, w, ROBUST_SHARPNESS[-1]))
    return np.asarray(smooth(jnp.asarray(values), jnp.asarray(omegas)))


def best_tunings(
    system: TIDSystem,
    amplitudes: ArrayLike,
    *,
    host_frequency_scales: ArrayLike = (1.0,),
    omegas: ArrayLike | None = None,
    settings: SolverSettings = SolverSettings(),
    max_steps: int = 60,
    tol: float = 1e-4,
    retune_settings: RetuneSettings = RetuneSettings(),
    progress: Callable[[str], None] | None = None,
) -> BestTunings:
    """The best achievable peak host displacement for each forcing amplitude (N) and host
    frequency scale (host stiffness times scale**2), over the band `omegas` (rad/s, for
    the nominal system; default `default_omegas(system)`) scaled with the host frequency.

    Every scenario is retuned by `retune`'s optimiser (`max_steps`, `tol`,
    `retune_settings` as there), all of them in one batch, from the system's tuning (k
    times scale**2, c times scale). `progress`, if given, gets a line as each step of the
    retune ends."""
    check_system(system)
    amps = _check_amplitudes(amplitudes)
    scales = _check_scales(host_frequency_scales)
    band = _band(system, omegas)
    check_retune_options(max_steps, tol, retune_settings)
    lane_scales, lane_amps = (g.reshape(-1) for g in np.meshgrid(scales, amps, indexing="ij"))
    bands = jnp.asarray(lane_scales[:, None] * np.asarray(band)[None])
    result = optimal_tunings(
        _scaled_lanes(system, lane_scales), jnp.asarray(lane_amps), bands, settings=settings,
        max_steps=max_steps, tol=tol, retune_settings=retune_settings, progress=progress,
    )
    # The robust design's reference: the peaks on the band's grid (see `robust_tune`),
    # which the check grid holds at every `check_refinement`-th point.
    on_band = np.asarray(result.x_response)[:, ::retune_settings.check_refinement]
    band_peaks = np.asarray(jax.vmap(lambda v, w: grid_peak(v, w)[0])(
        jnp.asarray(on_band), bands))
    shape = (scales.size, amps.size)
    grid = lambda a: jnp.asarray(np.asarray(a).reshape(shape))
    return BestTunings(
        system=system,
        omegas=band,
        amplitudes=jnp.asarray(amps),
        host_frequency_scales=jnp.asarray(scales),
        tid_stiffness=grid(result.tid_stiffness),
        tid_damping=grid(result.tid_damping),
        host_peak=grid(band_peaks),
        stroke_peak=grid(result.y_peak),
        objective=grid(_smooth_objective(on_band, bands)),
        iterations=grid(result.iterations),
        stationary=grid(np.asarray(result.status) != 1),
        converged=grid(result.converged),
        damping_at_bound=grid(result.damping_at_bound),
    )


class TuningPerformance(eqx.Module):
    """One tuning against the best achievable, over the scenarios of a `BestTunings`.
    Arrays are `[scales, amps]`; SI.

    - `host_peak`, `stroke_peak`: peak |x| and |y| over the band, m.
    - `ratio`: `host_peak` over the best achievable host peak.
    - `worst_ratio`, and the `worst_amplitude` (N) and `worst_host_frequency_scale` where
      it occurs; `max_stroke`: the largest `stroke_peak`, m.
    - `converged`: every steady state in the band converged.
    """

    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    amplitudes: Float[Array, " amps"]
    host_frequency_scales: Float[Array, " scales"]
    host_peak: Float[Array, "scales amps"]
    stroke_peak: Float[Array, "scales amps"]
    ratio: Float[Array, "scales amps"]
    worst_ratio: Float[Array, ""]
    worst_amplitude: Float[Array, ""]
    worst_host_frequency_scale: Float[Array, ""]
    max_stroke: Float[Array, ""]
    converged: Bool[Array, "scales amps"]


def _scaled_system(system: TIDSystem, scale: float, k: float, c: float) -> TIDSystem:
    return system.replace(
        host_stiffness=float(system.host_stiffness) * scale**2, tid_stiffness=k, tid_damping=c
    )


def _peaks_per_scale(system, k, c, amplitudes, scales, omegas, settings):
    """Host and inerter peaks (m; on the grid, refined by parabolas, as the robust design
    judges them) and convergence `[scales, amps]` of the tuning (k, c), over `omegas`
    (rad/s) times each scale."""
    x, y, ok = (np.zeros((len(scales), len(amplitudes))) for _ in range(3))
    for i, scale in enumerate(scales):
        grid = np.asarray(omegas) * float(scale)
        response = frequency_response(_scaled_system(system, float(scale), k, c), grid,
                                      np.asarray(amplitudes), settings=settings)
        on_grid = jax.vmap(grid_peak, (0, None))
        x[i] = on_grid(response.x_max, jnp.asarray(grid))[0]
        y[i] = on_grid(response.y_max, jnp.asarray(grid))[0]
        ok[i] = np.all(np.asarray(response.converged), axis=-1)
    return x, y, ok.astype(bool)


def _same(a: float | None, b: float | None) -> bool:
    """Two field values agree (`None`, the default friction width, only with itself)."""
    if a is None or b is None:
        return a is b
    return bool(np.isclose(a, b, rtol=1e-12, atol=0.0))


def _check_best(best, system: TIDSystem) -> None:
    if not isinstance(best, BestTunings):
        raise ValueError(f"best must be a BestTunings, got {type(best).__name__}")
    nominal = best.system.to_dict()
    given = system.to_dict()
    different = [
        name
        for name in FIELD_NAMES
        if name not in ("tid_stiffness", "tid_damping")
        and not _same(nominal[name], given[name])
    ]
    if different:
        raise ValueError(
            f"best was computed for another system: {different[0]} is "
            f"{nominal[different[0]]!r} there and {given[different[0]]!r} here"
        )


def tuning_performance(
    system: TIDSystem, best: BestTunings, *, settings: SolverSettings = SolverSettings()
) -> TuningPerformance:
    """The system's tuning over the scenarios of `best` (same band, amplitudes and host
    frequency scales): its host and inerter peaks (by `peaks`) and the ratio of its host
    peak to the best achievable, with the worst case and where it occurs."""
    check_system(system)
    _check_best(best, system)
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    amps = np.asarray(best.amplitudes)
    scales = np.asarray(best.host_frequency_scales)
    x, y, ok = _peaks_per_scale(system, k, c, amps, scales, best.omegas, settings)
    ratio = x / np.asarray(best.host_peak)
    i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return TuningPerformance(
        tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c),
        amplitudes=jnp.asarray(amps),
        host_frequency_scales=jnp.asarray(scales),
        host_peak=jnp.asarray(x),
        stroke_peak=jnp.asarray(y),
        ratio=jnp.asarray(ratio),
        worst_ratio=jnp.asarray(ratio[i, j]),
        worst_amplitude=jnp.asarray(amps[j]),
        worst_host_frequency_scale=jnp.asarray(scales[i]),
        max_stroke=jnp.asarray(float(np.max(y))),
        converged=jnp.asarray(ok),
    )


class RobustDesign(eqx.Module):
    """One TID tuning for a range of forcing amplitudes (and host frequencies): the one
    minimising the worst case over them of the peak host displacement relative to the best
    achievable at that amplitude, with the inerter stroke within a limit. SI units.

    - `tid_stiffness` (N/m), `tid_damping` (N s/m): the robust tuning.
    - `worst_ratio`: its largest peak ratio over the scenarios, at `worst_amplitude` (N) and
      `worst_host_frequency_scale`.
    - `stroke_limit`, `max_stroke` (m): the limit and the largest inerter peak, the latter
      on a grid `CHECK_REFINEMENT` times finer than the design band;
      `stroke_margin = 1 - max_stroke / stroke_limit`.
    - `performance`: the robust tuning's `TuningPerformance` on the design band (its
      `ratio` per scenario); `check_stroke_peak`: inerter peaks `[scales, amps]` on the
      fine grid, `check_converged`: whether every steady state there converged; `best`:
      the `BestTunings` it was measured against.
    - `iterations`: Newton steps; `converged`; `status`: see `status_messages()`.
    """

    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    worst_ratio: Float[Array, ""]
    worst_amplitude: Float[Array, ""]
    worst_host_frequency_scale: Float[Array, ""]
    stroke_limit: Float[Array, ""]
    max_stroke: Float[Array, ""]
    stroke_margin: Float[Array, ""]
    performance: TuningPerformance
    check_stroke_peak: Float[Array, "scales amps"]
    check_converged: Bool[Array, "scales amps"]
    best: BestTunings
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    status: Int[Array, ""]

    def status_messages(self) -> list[str]:
        """The meaning of `status`, one message per entry (one here), as
        `RetuneResult.status_messages`."""
        return [ROBUST_STATUS_MESSAGES[int(code)] for code in np.atleast_1d(self.status)]


def _check_stroke_limit(stroke_limit) -> float:
    if isinstance(stroke_limit, bool) or not isinstance(stroke_limit, int | float):
        raise ValueError(f"stroke_limit must be a number, got {stroke_limit!r}")
    if not (np.isfinite(stroke_limit) and stroke_limit > 0):
        raise ValueError(f"stroke_limit must be finite and positive, got {stroke_limit!r}")
    return float(stroke_limit)


def _robust_start(system, best: BestTunings, target, settings) -> tuple[float, float]:
    """The start of the robust search: of the system's tuning and the best tunings of the
    nominal host frequency, the one with the smallest worst-case ratio among those within
    the stroke target, or with the smallest stroke if none is."""
    scales = np.asarray(best.host_frequency_scales)
    nominal = int(np.argmin(np.abs(np.log(scales))))
    candidates = [(float(system.tid_stiffness), float(system.tid_damping))] + list(
        zip(
            np.asarray(best.tid_stiffness)[nominal].tolist(),
            np.asarray(best.tid_damping)[nominal].tolist(),
            strict=True,
        )
    )
    scores = []
    for k, c in candidates:
        x, y, _ = _peaks_per_scale(
            system, k, c, np.asarray(best.amplitudes), scales, best.omegas, settings
        )
        worst = float(np.max(np.log(x / np.asarray(best.host_peak))))
        excess = float(np.log(np.max(y))) - target if target is not None else 0.0
        scores.append((max(excess, 0.0), worst))
    return candidates[min(range(len(candidates)), key=scores.__getitem__)]


def robust_tune(
    system: TIDSystem,
    amplitudes: ArrayLike = PAPER_AMPLITUDES,
    *,
    host_frequency_scales: ArrayLike = (1.0,),
    stroke_limit: float | None = PAPER_STROKE,
    best: BestTunings | None = None,
    omegas: ArrayLike | None = None,
    settings: SolverSettings = SolverSettings(),
    max_steps: int = 40,
    tol: float = 1e-9,
    retune_settings: RetuneSettings = RetuneSettings(),
    progress: Callable[[str], None] | None = None,
) -> RobustDesign:
    """One TID stiffness k and damping c for every forcing amplitude in `amplitudes` (N;
    default the paper's, 100-3000 N) and host frequency scale in `host_frequency_scales`
    (e.g. (0.95, 1, 1.05) for +-5% host frequency; a scale s multiplies the host stiffness
    by s**2): the minimiser of the worst case, over these scenarios, of the peak host
    displacement over the band (`omegas`, rad/s, default `default_omegas(system)`, scaled
    with the host frequency) divided by the best achievable in that scenario, subject to
    the inerter stroke |y| <= `stroke_limit` (m).

    The best achievable peaks come from `best` if given (a `BestTunings` for the same
    system, amplitudes and scales), else from `best_tunings` (with `retune_settings`).
    The worst case is a smooth
    maximum, with sharpness rising over `ROBUST_SHARPNESS`, of the scenarios' log peak
    ratios. It is minimised by sequential quadratic programming with the smooth maximum of
    the log inerter peaks held below the limit (aimed `STROKE_MARGIN` below it): trust-region
    Newton steps, aiming at a decrement along the constraint below `tol` (converged within
    `NOISE_FACTOR * tol`), at most `max_steps` steps per stage, from the system's tuning
    or the best tuning of a nominal scenario, whichever has the smaller worst case within
    the limit. The stroke is then checked on a grid `CHECK_REFINEMENT` times finer; if it
    is over the limit there, the target is lowered by the excess and the design polished
    again. `stroke_limit=None` leaves the stroke free (reported with an infinite limit).
    `progress`, if given, gets one-line messages.
    """
    check_system(system)
    amps = _check_amplitudes(amplitudes)
    scales = _check_scales(host_frequency_scales)
    if not isinstance(retune_settings, RetuneSettings):
        raise ValueError("retune_settings must be a RetuneSettings, got "
                         f"{type(retune_settings).__name__}")
    limit = np.inf if stroke_limit is None else _check_stroke_limit(stroke_limit)
    check_optimiser_options(max_steps, tol)
    say = progress if progress is not None else (lambda message: None)
    if best is None:
        best = best_tunings(
            system,
            amps,
            host_frequency_scales=scales,
            omegas=omegas,
            settings=settings,
            retune_settings=retune_settings,
            progress=progress,
        )
    else:
        _check_best(best, system)
        for name, given in (("amplitudes", amps), ("host_frequency_scales", scales)):
            stored = np.asarray(getattr(best, name))
            if stored.shape != given.shape or not np.allclose(stored, given, rtol=1e-12):
                raise ValueError(f"{name} {given.tolist()} differ from best's {stored.tolist()}")
        if omegas is not None:
            band = _band(system, omegas)
            if band.shape != best.omegas.shape or not np.allclose(band, best.omegas):
                raise ValueError("omegas differ from the band best was computed on")
    band = np.asarray(best.omegas)
    # The worst case over scenarios is of the peaks on the band's grid (refined by
    # parabolas), as its reference `best.objective` is: the stroke limit is then checked
    # on a grid CHECK_REFINEMENT times finer.
    ctx = _Context(system, band, settings, locate=False)
    scenarios = [
        _Scenario(float(amplitude), float(scale), float(best.objective[i, j]))
        for i, scale in enumerate(scales)
        for j, amplitude in enumerate(amps)
    ]
    target = np.log(limit * (1 - STROKE_MARGIN)) if np.isfinite(limit) else None
    say(f"robust tuning over {len(scenarios)} scenarios, stroke limit {limit:g} m")
    k, c = _robust_start(system, best, target, settings)
    say(f"starting from k = {k:.6g} N/m, c = {c:.5g} N s/m")
    minimum = _minimise(
        ctx,
        scenarios,
        ctx.design(k, c, floor=_MIN_DAMPING_START),
        stroke_log_limit=target,
        max_steps=max_steps,
        tol=tol,
        say=say,
    )
    steps = minimum.steps
    fine = np.linspace(band[0], band[-1], CHECK_REFINEMENT * (band.size - 1) + 1)
    for round_ in range(_STROKE_ROUNDS + 1):
        k, c = ctx.tuning(minimum.evaluation.u)
        _, check_y, check_ok = _peaks_per_scale(system, k, c, amps, scales, fine, settings)
        max_stroke = float(np.max(check_y))
        if max_stroke <= limit or round_ == _STROKE_ROUNDS:
            break
        target -= np.log(max_stroke / limit) + STROKE_MARGIN
        say(f"stroke {max_stroke:.5g} m over the limit on the check grid: aiming lower")
        states = [curves.states for curves in minimum.evaluation.centres()]
        minimum = _minimise(
            ctx,
            scenarios,
            minimum.evaluation.u,
            stroke_log_limit=target,
            z_inits=states,
            stages=ROBUST_SHARPNESS[-1:],
            max_steps=max_steps,
            tol=tol,
            say=say,
        )
        steps += minimum.steps
    performance = tuning_performance(
        system.replace(tid_stiffness=k, tid_damping=c), best, settings=settings
    )
    steady = bool(np.all(performance.converged) and np.all(check_ok))
    status = 1 if not minimum.converged else 2 if not steady else 3 if max_stroke > limit else 0
    say(
        f"robust tuning: k = {k:.6g} N/m, c = {c:.5g} N s/m, worst ratio "
        f"{float(performance.worst_ratio):.4f} at {float(performance.worst_amplitude):g} N; "
        f"{ROBUST_STATUS_MESSAGES[status]}"
    )
    return RobustDesign(
        tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c),
        worst_ratio=performance.worst_ratio,
        worst_amplitude=performance.worst_amplitude,
        worst_host_frequency_scale=performance.worst_host_frequency_scale,
        stroke_limit=jnp.asarray(limit),
        max_stroke=jnp.asarray(max_stroke),
        stroke_margin=jnp.asarray(1 - max_stroke / limit),
        performance=performance,
        check_stroke_peak=jnp.asarray(check_y),
        check_converged=jnp.asarray(check_ok),
        best=best,
        iterations=jnp.asarray(steps),
        converged=jnp.asarray(status == 0),
        status=jnp.asarray(status),
    )
