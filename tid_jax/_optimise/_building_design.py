"""The peak of a `BuildingTID`'s response over frequency and the TID's retune per
amplitude: steady states on a frequency grid (`_building_orbit`), the two highest local
maxima refined by parabolas through ever closer frequencies, their exact derivatives
(implicit, through the periodic orbit), and the tuning (k, c) that minimises the
highest: the minimax of the two peaks by SLSQP (scipy) on its epigraph form, shared
with the robust design (`minimax`)."""


import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize
from jaxtyping import Array, Bool, Float

from .._model._building import (
    BuildingTID,
    Quantity,
    first_mode_tunings,
    linear_amplitudes,
    log_tuned,
    log_tuning_of,
    quantity_amplitude,
)
from .._model._checks import check_grid
from .._orbit._building_orbit import (
    building_settings,
    period_end,
    period_samples,
    solve_orbit,
)
from .._orbit._flow import flow, plant, projection_units
from .._orbit._implicit import fixed_point_matrix
from .._orbit._sampled_peaks import local_peaks, refined_peak
from .._orbit._settings import SolverSettings
from .._runtime._outcomes import Outcome

# The default band of a building's design: these multiples of the bare structure's
# first natural frequency.
BUILDING_BAND = (0.5, 1.6)
BAND_POINTS = 31
_CANDIDATES = 2  # local maxima refined
_ROUNDS = 6  # parabolas through ever closer frequencies
_SHRINK = 4.0
_CHUNK = 3 * _CANDIDATES  # orbits solved together: a round's
# the retune's range: k and c within these factors of the first mode's H-infinity tuning
_RANGE = (4.0, 30.0)
_PENALTY = 1.0  # log peak given to a design whose steady states were not all found
_STALL = 12  # evaluations without a gain of rtol in the log peak that end a search
# a search that ends otherwise has converged where no change of log k and log c within
# _REACH lowers the highest log peak by more than _GAIN to first order
_REACH = 1e-2
_GAIN = 1e-4


class _Stalled(Exception):
    pass


def first_mode_band(system: BuildingTID, points: int = BAND_POINTS) -> np.ndarray:
    """`points` frequencies (rad/s) over `BUILDING_BAND` of the first mode."""
    return np.linspace(*BUILDING_BAND, points) * system.structure.modes()[0][0]


def search_grid(system: BuildingTID, omegas) -> np.ndarray:
    """The grid the peaks are looked for on: `omegas` (default `first_mode_band`), or
    `BAND_POINTS` frequencies evenly over their range where they are fewer (a coarser
    grid can merge the two peaks)."""
    if omegas is None:
        return first_mode_band(system)
    omegas = np.asarray(check_grid("omegas", omegas), float)
    if omegas.size < BAND_POINTS:
        return np.linspace(omegas.min(), omegas.max(), BAND_POINTS)
    return omegas


class Peak(eqx.Module):
    value: Float[Array, ""]  # SI
    omega: Float[Array, ""]  # rad/s
    converged: Bool[Array, ""]  # every steady state it rests on was found


class Band(eqx.Module):
    """The steady states over a frequency grid and the two candidates for the peak."""

    peak: Peak
    values: Float[Array, " candidates"]  # the candidates' refined peaks, SI
    omegas: Float[Array, " candidates"]  # the last frequencies solved about them, rad/s
    states: Float[Array, "candidates s"]  # the orbits there
    grid_states: Float[Array, "freqs s"]
    grid_monodromies: Float[Array, "freqs s s"]


def _solve(system, quantity, amplitude, omegas, settings, linear, start, cold=None):
    """Values, convergence, states and monodromy matrices at `omegas`, from `start`
    (states, monodromy matrices per frequency; see `solve_orbit`)."""
    if linear:  # no friction: the steady state in closed form
        u = linear_amplitudes(system, omegas)
        value = amplitude * jnp.abs(quantity_amplitude(system, quantity, omegas, u))
        return value, jnp.isfinite(value), start[0], start[1]
    orbits = jax.vmap(lambda w, z, m: solve_orbit(system, quantity, amplitude, w, settings,
                                                  start=(z, m), cold=cold))(omegas, *start)
    return orbits.response_max, orbits.converged, orbits.state, orbits.monodromy


def _candidates(values, omegas):
    """Grid indices of the two highest local maxima (a band end counts where it is above
    its neighbour), in order; the highest twice where there is one."""
    peaks, at, is_peak = local_peaks(values, omegas)
    ends = jnp.zeros_like(is_peak).at[0].set(values[0] > values[1]).at[-1].set(
        values[-1] > values[-2])
    score = jnp.where(is_peak | ends, peaks, -jnp.inf)
    order = jnp.argsort(-score)[:_CANDIDATES]
    # (in order of frequency: each design's candidates are the same peaks)
    return jnp.sort(jnp.where(jnp.isfinite(score[order]), order, order[0])), peaks, at


def no_start(system: BuildingTID, points: int):
    """A start for `points` orbits that has none: each from its linear equivalent."""
    s = 2 * system.coordinates
    return jnp.zeros((points, s)), jnp.full((points, s, s), np.nan, dtype=float)


def peak_over_frequency(system: BuildingTID, quantity: Quantity, amplitude, omegas,
                        settings: SolverSettings, linear: bool = False, start=None) -> Band:
    """The largest steady-state peak of `quantity` over the band of `omegas`: the grid's
    two highest local maxima (or band ends), each refined `_ROUNDS` times by the vertex
    of the parabola through three frequencies about it, their spacing shrinking where
    the middle one is the highest (else a step uphill), every orbit started from the
    last round's. `linear`: the system has no
    friction, and its steady states are found in closed form. `start`: states and
    monodromy matrices on the grid of a nearby design (`no_start`: none, and every orbit,
    the rounds' too, starts from its linear equivalent).

    The grid is solved in chunks of `_CHUNK` frequencies, the size of a round, all in
    one loop: one compiled copy of the solver, and no orbit waits for the slowest of
    the whole grid."""
    count = omegas.shape[0]
    chunks = -(-count // _CHUNK)
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], chunks * _CHUNK - count, axis=0)])
    start = no_start(system, count) if start is None else start
    cold = ~jnp.all(jnp.isfinite(start[1]))
    grid_omegas, starts = pad(omegas), jax.tree.map(pad, start)
    step = (omegas[1] - omegas[0]) / _SHRINK
    take = lambda x, i: jax.lax.dynamic_slice_in_dim(x, i * _CHUNK, _CHUNK)

    def body(i, state):
        grid, centres, _, best, z, m, width, all_ok = state
        on_grid = i < chunks
        index, peaks, at = _candidates(jnp.where(grid[1], grid[0], jnp.inf)[:count], omegas)
        first = i == chunks
        centres = jnp.where(first, at[index], centres)
        best = jnp.where(first, peaks[index], best)
        z, m = jnp.where(first, grid[2][index], z), jnp.where(first, grid[3][index], m)
        around = jnp.clip(centres[:, None] + width[:, None] * jnp.asarray([-1.0, 0.0, 1.0]),
                          omegas[0], omegas[-1])
        j = jnp.minimum(i, chunks - 1)
        points = jnp.where(on_grid, take(grid_omegas, j), around.reshape(-1))
        near = jax.tree.map(lambda g, r: jnp.where(on_grid, take(g, j), jnp.repeat(r, 3, axis=0)),
                            starts, (z, m))
        v, ok, zs, ms = _solve(system, quantity, amplitude, points, settings, linear, near,
                               cold)
        grid = jax.tree.map(
            lambda g, new: jnp.where(on_grid, jax.lax.dynamic_update_slice_in_dim(
                g, new, j * _CHUNK, 0), g), grid, (v, ok, zs, ms))
        v = v.reshape(around.shape)
        left, mid, right = v[:, 0], v[:, 1], v[:, 2]
        curvature = left - 2 * mid + right
        # bracketed: the vertex, and the spacing shrinks; else a step uphill
        concave = (curvature < 0) & (mid >= left) & (mid >= right)
        shift = jnp.where(concave, 0.5 * (left - right) / jnp.where(concave, curvature, -1.0),
                          jnp.where(left > right, -1.0, 1.0))
        refined = jnp.where(concave, mid - 0.125 * (right - left) ** 2 / jnp.where(
            concave, curvature, -1.0), jnp.max(v, axis=1))
        rounds = (jnp.clip(centres + shift * width, omegas[0], omegas[-1]), around[:, 1],
                  refined, zs[1::3], ms[1::3], jnp.where(concave, width / _SHRINK, width),
                  all_ok & jnp.all(ok))
        return (grid,) + jax.tree.map(lambda a, b: jnp.where(on_grid, a, b), state[1:], rounds)

    s = 2 * system.coordinates
    dtype = grid_omegas.dtype
    grid = (jnp.zeros_like(grid_omegas), jnp.zeros(grid_omegas.shape, bool), starts[0],
            starts[1])
    pair = jnp.zeros(_CANDIDATES, dtype)
    state = (grid, pair, pair, pair, jnp.zeros((_CANDIDATES, s), dtype),
             jnp.zeros((_CANDIDATES, s, s), dtype), jnp.full(_CANDIDATES, step, dtype),
             jnp.asarray(True))
    grid, centres, mids, best, z, _, _, ok = jax.lax.fori_loop(0, chunks + _ROUNDS, body,
                                                               state)
    ok = ok & jnp.all(grid[1][:count]) & jnp.all(jnp.isfinite(best))
    top = jnp.argmax(best)
    return Band(Peak(best[top], centres[top], ok), best, mids, z, grid[2][:count],
                grid[3][:count])


def peak_derivatives(system: BuildingTID, quantity: Quantity, amplitude, omega, state,
                     settings: SolverSettings, linear: bool, change, count: int):
    """The derivatives of the steady-state peak of `quantity` at `omega` (SI) along each
    of `count` coordinates theta, at theta = 0, of `change(theta) -> (system,
    amplitude)`: those of the peak over frequency too where `omega` is its frequency
    (the envelope theorem). They are implicit, given the periodic `state` of `system`
    at `amplitude`: the derivatives of one Newton step from it, with its monodromy
    matrix held. `linear`: no friction, the steady state in closed form."""
    if linear:
        def value(theta):
            changed, a = change(theta)
            u = linear_amplitudes(changed, omega[None])
            return a * jnp.abs(quantity_amplitude(changed, quantity, omega[None], u))[0]
    else:
        pl = plant(system, quantity, amplitude, omega)
        fl = flow(pl, settings.samples) if settings.exact_friction else None
        basis = jnp.eye(state.shape[0], dtype=state.dtype)
        monodromy = jax.vmap(lambda t: jax.jvp(lambda z: period_end(z, pl, fl, settings),
                                               (state,), (t,))[1], out_axes=1)(basis)
        lu = jax.scipy.linalg.lu_factor(fixed_point_matrix(monodromy))

        def value(theta):
            changed, a = change(theta)
            pl = plant(changed, quantity, a, omega)
            fl = flow(pl, settings.samples) if settings.exact_friction else None
            newton = state + jax.scipy.linalg.lu_solve(lu, period_end(state, pl, fl, settings)
                                                       - state)
            samples = period_samples(newton, pl, fl, settings)[0][:, 0]
            return refined_peak(samples) * projection_units(changed, quantity, a, omega)[0]
    origin = jnp.zeros(count, dtype=state.dtype)
    return jax.vmap(lambda t: jax.jvp(value, (origin,), (t,))[1])(
        jnp.eye(count, dtype=state.dtype))


def peak_gradient(system: BuildingTID, quantity: Quantity, amplitude, omega, state,
                  settings: SolverSettings, linear: bool):
    """The derivatives of the steady-state peak at `omega` with respect to (log k,
    log c) (`peak_derivatives`)."""
    log_tuning = log_tuning_of(system)
    return peak_derivatives(system, quantity, amplitude, omega, state, settings, linear,
                            lambda theta: (log_tuned(system, log_tuning + theta), amplitude), 2)


class BuildingRetune(eqx.Module):
    """The minimax tuning per amplitude (SI): `tid_stiffness` k (N/m), `tid_damping` c
    (N s/m), `peak` (of the quantity over the band; NaN where the search did not end at
    a first-order minimax point), and `converged`: where it did, within the band (not at
    an end of it)."""

    tid_stiffness: Float[Array, " amps"]
    tid_damping: Float[Array, " amps"]
    peak: Float[Array, " amps"]
    converged: Bool[Array, " amps"]


@eqx.filter_jit
def _evaluate(system, quantity, amplitude, omegas, start, settings, linear):
    """A design's band (`peak_over_frequency`, from `start`), and the two candidate
    peaks and their derivatives (`peak_gradient`, the frequency of each held)."""
    band = peak_over_frequency(system, quantity, amplitude, omegas, settings, linear, start)
    gradients = jax.vmap(lambda w, z: peak_gradient(system, quantity, amplitude, w, z,
                                                    settings, linear))(band.omegas, band.states)
    ok = band.peak.converged & jnp.all(jnp.isfinite(gradients))
    return band, band.values, gradients, ok


class BandSearch:
    """One scenario (a system and an amplitude) on the host: every design (log k, log c)
    evaluated once, each from the orbits of the last that was found."""

    def __init__(self, system, quantity, amplitude, omegas, settings, linear):
        self.args = (quantity, jnp.asarray(amplitude), jnp.asarray(omegas))
        self.system, self.settings, self.linear = system, settings, linear
        self.start = no_start(system, omegas.shape[0])
        self.seen = {}

    def __call__(self, x):
        """The log peaks of the two candidates, their gradients, whether they were found
        and the `Peak` of design `x`."""
        key = tuple(np.asarray(x[:2], float))
        if key not in self.seen:
            design = log_tuned(self.system, jnp.asarray(key))
            band, values, gradients, ok = _evaluate(design, *self.args, self.start,
                                                    self.settings, self.linear)
            ok = bool(ok)
            if not ok and bool(jnp.all(jnp.isfinite(self.start[1]))):  # again, cold
                band, values, gradients, ok = _evaluate(
                    design, *self.args, no_start(design, self.args[2].shape[0]),
                    self.settings, self.linear)
                ok = bool(ok)
            if ok:
                self.start = (band.grid_states, band.grid_monodromies)
            values = np.asarray(values)
            self.seen[key] = (np.log(values), np.asarray(gradients) / values[:, None], ok,
                              band.peak)
        return self.seen[key]


class _Minimax:
    """The highest of the scenarios' log peaks less their `offsets`, as SLSQP's
    constraints, with the best feasible design so far; a search that gains less than
    `rtol` in `_STALL` evaluations is stopped (`_Stalled`). `limits(x) -> (values,
    gradients)` (and `limits.values(x)`, the values alone): further constraints,
    values <= 0, a design feasible where each is within `slack`."""

    def __init__(self, searches, offsets, rtol, limits=None, slack=0.0):
        self.searches, self.offsets, self.rtol = searches, np.asarray(offsets, float), rtol
        self.limits, self.slack = limits, slack
        self.stalled, self.seen = 0, set()
        self.best = None  # (worst, x, log peaks less offsets, gradients)

    def limit_rows(self, v):
        """The further constraints' values and gradients at `v`, `_PENALTY` (flat) where
        one was not found."""
        values, gradients = self.limits(v[:2])
        values, gradients = np.asarray(values, float), np.asarray(gradients, float)
        found = np.isfinite(values) & np.all(np.isfinite(gradients), axis=1)
        return (np.where(found, values, _PENALTY),
                np.where(found[:, None], gradients, 0.0))

    def feasible(self, x) -> bool:
        """Whether every further constraint (`limits.values`) is within `slack` at x."""
        if self.limits is None:
            return True
        values = np.asarray(self.limits.values(x[:2]), float)
        return bool(np.all(np.isfinite(values) & (values <= self.slack)))

    def __call__(self, x):
        found = [search(x) for search in self.searches]
        ok = all(f[2] for f in found)
        logs = np.concatenate([f[0] - offset for f, offset in zip(found, self.offsets,
                                                                   strict=True)])
        slopes = np.concatenate([f[1] for f in found])
        key = tuple(np.asarray(x[:2], float))
        if key not in self.seen:
            self.seen.add(key)
            self.stalled += self.best is not None  # (none yet: still looking for one)
            if ok and (self.best is None or logs.max() < self.best[0]) and self.feasible(x):
                if self.best is None or logs.max() < self.best[0] - self.rtol:
                    self.stalled = 0
                self.best = (logs.max(), np.asarray(key), logs, slopes)
            if self.stalled > _STALL:
                raise _Stalled
        return logs, slopes, ok

    def stationary(self) -> bool:
        """Whether the best design is a minimax point to first order: no change of k and
        c within a factor exp(`_REACH`) lowers the highest log peak by more than `_GAIN`
        in the peaks' linear model (a linear program)."""
        top, _, logs, slopes = self.best
        # min t over (dlog k, dlog c, t) subject to logs + slopes . d <= t
        rows, bounds = np.column_stack([slopes, -np.ones(len(logs))]), -logs
        if self.limits is not None:  # and the further constraints' linear models
            values, gradients = self.limit_rows(self.best[1])
            rows = np.vstack([rows, np.column_stack([gradients, np.zeros(len(values))])])
            bounds = np.concatenate([bounds, np.maximum(-values, 0.0)])
        model = scipy.optimize.linprog([0.0, 0.0, 1.0], A_ub=rows, b_ub=bounds,
                                       bounds=[(-_REACH, _REACH)] * 2 + [(None, None)])
        return bool(model.status == 0 and top - model.fun <= _GAIN)

    def constraints(self, v):
        logs, _, ok = self(v)
        worst = self.best[0] + _PENALTY if self.best is not None else _PENALTY
        return v[2] - (logs if ok else np.full(logs.shape, worst))

    def jacobian(self, v):
        logs, slopes, ok = self(v)
        rows = np.zeros((logs.size, 3))
        rows[:, 2] = 1.0
        if ok:
            rows[:, :2] = -slopes
        return rows


def minimax(searches, offsets, x0, centre, rtol: float, max_steps: int, limits=None,
            slack: float = 0.0):
    """The design (log k, log c) that minimises the highest over the `searches`
    (`BandSearch`) of their log peaks less `offsets`: SLSQP (scipy) on the epigraph form,
    min t subject to every log peak less its offset <= t and, if given, `limits(x) ->
    (values, gradients)` <= 0 (see `_Minimax`), from `x0` and within `_RANGE` of
    `centre`. Returns the best design (feasible: each limit within `slack`), its worst
    value and whether the search converged (SLSQP's test, or a stall at a first-order
    minimax point); None where the start was not found, or no feasible design was."""
    problem = _Minimax(searches, offsets, rtol, limits, slack)
    logs, _, ok = problem(x0)
    if not ok:
        return None
    bounds = [(x - np.log(r), x + np.log(r)) for x, r in zip(centre, _RANGE, strict=True)]
    constraints = [{"type": "ineq", "fun": problem.constraints, "jac": problem.jacobian}]
    if limits is not None:
        constraints.append({
            "type": "ineq", "fun": lambda v: -problem.limit_rows(v)[0],
            "jac": lambda v: np.column_stack([-problem.limit_rows(v)[1],
                                              np.zeros(len(problem.limit_rows(v)[0]))])})
    try:
        solution = scipy.optimize.minimize(
            lambda v: v[2], np.append(x0, logs.max()), jac=lambda v: np.eye(3)[2],
            method="SLSQP", bounds=bounds + [(None, None)],
            options={"ftol": rtol, "maxiter": max_steps}, constraints=constraints)
        success = solution.success
    except _Stalled:
        success = False
    if problem.best is None:
        return None
    return problem.best[1], problem.best[0], success or problem.stationary()


def _retune_one(system, quantity, amplitude, omegas, tunings, settings, rtol, max_steps,
                linear):
    """The retune at one amplitude (`minimax` of one scenario), from the better of the
    first mode's tunings and within `_RANGE` of its H-infinity tuning. Returns the
    tuning, its `Peak` and the `Outcome` of the search (ok, not_stationary, or
    steady_states_failed where no start was found); `tunings`: name -> (k, c)."""
    search = BandSearch(system, quantity, amplitude, omegas, settings, linear)
    starts = {}
    for name, tuning in tunings.items():
        logs, _, ok, _ = search(np.log(np.asarray(tuning, float)))
        starts[name] = logs.max() if ok else np.inf
    centre = np.log(np.asarray(tunings["h_infinity"], float))
    first = min(starts, key=starts.get)
    found = None
    if np.isfinite(starts[first]):
        found = minimax([search], [0.0], np.log(np.asarray(tunings[first], float)), centre,
                        rtol, max_steps)
    if found is None:
        return np.exp(centre), None, Outcome.steady_states_failed
    x, _, ok = found
    return np.exp(x), search(x)[3], Outcome.ok if ok else Outcome.not_stationary


def at_band_edge(omega_peak, omegas) -> np.ndarray:
    """Whether each peak frequency `omega_peak` (rad/s) is at an end of the band `omegas`
    (`peak_over_frequency` holds a peak there exactly, its refinement clipped to the
    band)."""
    omega_peak, omegas = np.asarray(omega_peak), np.asarray(omegas)
    return (omega_peak <= omegas.min()) | (omega_peak >= omegas.max())


def frictionless(system: BuildingTID) -> bool:
    """Whether the system is linear: no friction and no backlash."""
    return bool(np.all(np.asarray(system.friction_force) == 0)
                and np.all(np.asarray(system.backlash) == 0))


def retune_building(system: BuildingTID, amplitudes, quantity: Quantity = Quantity(), *,
                    omegas=None, settings: SolverSettings | None = None,
                    rtol: float = 1e-6, max_steps: int = 100) -> BuildingRetune:
    """The TID's (k, c) that minimise the peak of `quantity` over the band of `omegas`
    (default `first_mode_band`; at least `BAND_POINTS` frequencies over their range) at
    each of `amplitudes`, the minimax point that the building's robust design and
    sensitivities start from: the whole structure and the friction seen by each steady
    state, the two highest peaks over frequency and their exact derivatives
    (`peak_gradient`) given to SLSQP (scipy) in the epigraph form (`_retune_one`), from
    the better of the first mode's tunings (`first_mode_tunings`) and within a factor
    `_RANGE` of its H-infinity one; `rtol`: the search's tolerance on the log peak."""
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    omegas = search_grid(system, omegas)
    quantity.floor_of(system.floors)
    settings = building_settings(system, settings)
    tunings = first_mode_tunings(system)
    linear = frictionless(system)
    w = jnp.asarray(omegas)
    rows = [_retune_one(system, quantity, jnp.asarray(amplitude), w, tunings, settings, rtol,
                        max_steps, linear) for amplitude in amplitudes]
    tuning = np.asarray([row[0] for row in rows])
    searched = np.asarray([row[2] == Outcome.ok for row in rows])
    omega_peak = np.asarray([np.nan if row[1] is None else float(row[1].omega)
                             for row in rows])
    return BuildingRetune(
        tid_stiffness=tuning[:, 0], tid_damping=tuning[:, 1],
        peak=np.asarray([float(row[1].value) if ok else np.nan
                         for row, ok in zip(rows, searched, strict=True)]),
        converged=searched & ~at_band_edge(omega_peak, omegas))
