import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

# The peak of a response over frequency is the maximum of a smooth function sampled on a
# grid. A grid peak is refined by the parabola through the largest sample and its
# neighbours; the true peak (the maximum in continuous frequency) by Newton steps on the
# slope of the response, each from a stencil of STENCIL_POINTS frequencies PEAK_STEP
# (relative) apart around the last estimate (the slope and curvature by central
# differences, the slope's error fourth order in the step), and is the response at the
# last iterate, which differs from the peak by the square of the iterate's distance from
# it. Only that response needs derivatives: those of the peak are the response's at its
# frequency (the envelope theorem), so the stencils are solved without them. Every step
# has the same stencil, so that a compiled program holds one copy of its solves (a loop).
PEAK_STEP = 2e-3
STENCIL_POINTS = 5
# Newton steps from the grid's parabola vertex: each squares the relative distance to the
# peak (in units of the peak's width). The peak's derivatives are first order in that
# distance: after two steps they were 1e-3 off differences of re-located peaks on the
# paper's system (21 frequencies), after three within 1e-4.
PEAK_NEWTON_STEPS = 3


# Local maxima located in continuous frequency per response: the two resonance peaks of a
# TID and one more (a band end, or a third local maximum).
REFINED_PEAKS = 3


def parabola_top(left, mid, right):
    """The vertex of the parabola through three equally spaced samples where `mid` is a
    local maximum of them and they are concave, else `mid` (elementwise)."""
    curvature = left - 2 * mid + right
    is_top = (mid >= left) & (mid >= right) & (curvature < 0)
    safe = jnp.where(is_top, curvature, -1.0)
    return jnp.where(is_top, mid - (right - left) ** 2 / (8 * safe), mid)


def refined_peak(samples: Float[Array, " n"]) -> Float[Array, ""]:
    """max |s(phase)| over a period from periodic samples, refined by the vertex of the
    parabola through the largest sample and its two neighbours."""

    def top(s):
        i = jnp.argmax(s)
        return parabola_top(s[i - 1], s[i], s[(i + 1) % s.shape[0]])

    return jnp.maximum(top(samples), top(-samples))


def parabola_vertices(values: Float[Array, " freqs"], omegas: Float[Array, " freqs"]):
    """At every interior sample of `values` on the (possibly non-uniform) grid `omegas`
    where the samples are concave, the vertex of the parabola through it and its
    neighbours: its value (no less than the sample's) and frequency (between the
    neighbours'); elsewhere the sample itself. Returns `(value, omega, is_peak)` for the
    interior points, `is_peak` marking the local maxima."""
    v0, v1, v2 = values[:-2], values[1:-1], values[2:]
    w0, w1, w2 = omegas[:-2], omegas[1:-1], omegas[2:]
    h0, h1 = w1 - w0, w2 - w1
    d0, d1 = (v1 - v0) / h0, (v2 - v1) / h1
    curvature = (d1 - d0) / (h0 + h1)  # half the second derivative
    concave = curvature < 0
    safe = jnp.where(concave, curvature, -1.0)
    slope = d0 + curvature * h0  # first derivative at w1
    shift = jnp.clip(-slope / (2 * safe), -h0, h1)
    vertex = v1 + slope * shift + safe * shift**2
    value = jnp.where(concave, jnp.maximum(vertex, v1), v1)
    omega = jnp.where(concave, w1 + shift, w1)
    return value, omega, (v1 >= v0) & (v1 >= v2) & concave


def local_peaks(values: Float[Array, " freqs"], omegas: Float[Array, " freqs"]):
    """Parabolic refinement of every interior local maximum of `values` on the (possibly
    non-uniform) grid `omegas`. Returns `(peak, omega_peak, is_peak)` per grid point: at
    local maxima the vertex of the parabola through the point and its neighbours, else the
    value itself with `is_peak` False."""
    vertex, omega_vertex, is_peak = parabola_vertices(values, omegas)
    peak = jnp.where(is_peak, vertex, values[1:-1])
    omega_peak = jnp.where(is_peak, omega_vertex, omegas[1:-1])
    edge = lambda a, i: jnp.concatenate([a[:1], i, a[-1:]])
    false = jnp.zeros(1, dtype=bool)
    return edge(values, peak), edge(omegas, omega_peak), jnp.concatenate([false, is_peak, false])


def grid_peak(values: Float[Array, " freqs"], omegas: Float[Array, " freqs"]):
    """The maximum over frequency of `values` sampled on `omegas`, refined by a parabola
    through the largest sample and its neighbours. Returns `(peak, omega_peak, at_edge)`."""
    peaks, omega_peaks, _ = local_peaks(values, omegas)
    i = jnp.argmax(peaks)
    return peaks[i], omega_peaks[i], (i == 0) | (i == values.shape[0] - 1)


@jax.jit
def lane_grid_peaks(values: Float[Array, "lanes freqs"], omegas: Float[Array, "lanes freqs"]):
    """`grid_peak` of each lane of `values` on its grid `omegas`, in one compiled program
    (not an array operation at a time)."""
    return jax.vmap(grid_peak)(values, omegas)


def _candidates(values, omegas):
    """Refined local maxima of `values` with the band ends: (peak, omega, is_candidate)."""
    peaks, omega_peaks, is_peak = local_peaks(values, omegas)
    return peaks, omega_peaks, is_peak.at[0].set(True).at[-1].set(True)


def smooth_log_peak(values: Float[Array, " freqs"], omegas, sharpness, true=None
                    ) -> Float[Array, ""]:
    """Smooth maximum (log-sum-exp with `sharpness`) of the logarithms of the refined local
    peaks of `values` (and of the band ends): it tends to log of `grid_peak` as the
    sharpness grows, and stays differentiable where two peaks are equal. With
    `true = (index, peaks)`, the local maxima at the grid indices `index` (from
    `top_peaks`) are the true `peaks` instead (-inf where the index holds no maximum)."""
    peaks, _, candidates = _candidates(values, omegas)
    logs = jnp.where(candidates, jnp.log(peaks), -jnp.inf)
    if true is not None:
        index, true_peaks = true
        logs = logs.at[index].set(jnp.where(candidates[index], jnp.log(true_peaks), -jnp.inf))
    return jax.nn.logsumexp(sharpness * logs) / sharpness


def top_peaks(values: Float[Array, " freqs"], omegas: Float[Array, " freqs"], count: int):
    """The `count` highest local maxima of `values` on the grid `omegas` (band ends
    included): their grid indices, the frequencies of their parabola vertices, and which of
    them are local maxima (fewer than `count` leave repeats marked False)."""
    peaks, omega_peaks, candidates = _candidates(jax.lax.stop_gradient(values), omegas)
    count = min(count, values.shape[0])
    _, index = jax.lax.top_k(jnp.where(candidates, peaks, -jnp.inf), count)
    return index, omega_peaks[index], candidates[index]


def bracket(index: Int[Array, " peaks"], omegas: Float[Array, " freqs"]):
    """The grid frequencies either side of each grid index (the ends' own at the ends):
    the interval a peak found at that index lies in; and whether the index is interior."""
    n = omegas.shape[0]
    lower = omegas[jnp.maximum(index - 1, 0)]
    upper = omegas[jnp.minimum(index + 1, n - 1)]
    return lower, upper, (index > 0) & (index < n - 1)


# Central-difference weights of the slope (times the step) and the curvature (times the
# step squared) on stencils of three and five frequencies.
_DIFFERENCES = {
    3: ((-0.5, 0.0, 0.5), (1.0, -2.0, 1.0)),
    5: ((1 / 12, -8 / 12, 0.0, 8 / 12, -1 / 12), (-1 / 12, 16 / 12, -30 / 12, 16 / 12, -1 / 12)),
}


def stencil(centre: Float[Array, " peaks"], interior: Bool[Array, " peaks"],
            points: int = STENCIL_POINTS):
    """`points` (3 or 5) frequencies `PEAK_STEP` (relative) apart around each `centre`;
    the centre repeated where the peak is at a band end (not `interior`)."""
    step = jnp.where(interior, PEAK_STEP * centre, 0.0)
    offsets = jnp.arange(points, dtype=centre.dtype) - points // 2
    return centre[:, None] + step[:, None] * offsets


def newton_peak(values: Float[Array, "peaks points"], omegas: Float[Array, "peaks points"],
                lower, upper, interior):
    """One Newton step on the slope of a response towards its maximum, from the values at
    the `stencil` frequencies `omegas` (central differences, second order on three
    frequencies, fourth order on five), kept within [`lower`, `upper`]: the maximum of the
    stencil's Taylor polynomial there, and its frequency. At a band end (not `interior`),
    or where the stencil is not concave, the largest of the values and its frequency;
    where a value is not finite, the largest (inf or NaN) and the stencil's centre.
    Differentiable in `values`."""
    points = values.shape[1]
    slope_weights, curvature_weights = (jnp.asarray(w, values.dtype)
                                        for w in _DIFFERENCES[points])
    mid = values[:, points // 2]
    h = jnp.where(interior, omegas[:, points // 2 + 1] - omegas[:, points // 2], 1.0)
    slope = values @ slope_weights / h
    curvature = values @ curvature_weights / h**2
    concave = interior & (curvature < 0)
    safe = jnp.where(concave, curvature, -1.0)
    centre = omegas[:, points // 2]
    shift = jnp.clip(-slope / safe, lower - centre, upper - centre)
    vertex = mid + slope * shift + safe * shift**2 / 2
    best = jnp.argmax(values, axis=1)
    largest = jnp.take_along_axis(values, best[:, None], axis=1)[:, 0]
    at_largest = jnp.take_along_axis(omegas, best[:, None], axis=1)[:, 0]
    # A value that is not finite (a steady state not found) is passed on: inf or NaN.
    finite = jnp.all(jnp.isfinite(values), axis=1)
    return (jnp.where(finite, jnp.where(concave, vertex, largest), jnp.max(values, axis=1)),
            jnp.where(finite, jnp.where(concave, centre + shift, at_largest), centre))


def interpolated(states: Float[Array, "freqs ..."], omegas: Float[Array, " freqs"], at):
    """`states` (one per grid frequency) interpolated linearly to the frequencies `at`."""
    flat = states.reshape(states.shape[0], -1)
    out = jax.vmap(lambda column: jnp.interp(at.reshape(-1), omegas, column), 1, -1)(flat)
    return out.reshape(at.shape + states.shape[1:])


def located_peak(estimate: Float[Array, " peaks"], value: Float[Array, " peaks"]):
    """The peak from the last Newton step's `estimate` (`newton_peak`) and the response
    `value` at its frequency: the value, unless the estimate is not finite (a stencil's
    steady state was not found), which is then passed on."""
    return jnp.where(jnp.isfinite(estimate), value, estimate)


def newton_iterates(solve, centre: Float[Array, " peaks"], interior: Bool[Array, " peaks"],
                    lower, upper, aux=()):
    """`PEAK_NEWTON_STEPS` Newton steps (`newton_peak`, a loop) from the frequencies
    `centre` towards the peaks, kept within [`lower`, `upper`]: `solve(at)` gives the
    response at each step's `stencil` frequencies `at` (peaks x points; no derivatives
    needed) and whatever else its solves give, `aux` (a pytree of arrays of the shapes of
    the one given, which stands before the first step). Returns the last step's estimate
    of each peak and its frequency, that step's stencil and its `aux`."""

    def step(_, carry):
        at = stencil(jax.lax.stop_gradient(carry[1]), interior)
        values, aux = solve(at)
        return *newton_peak(values, at, lower, upper, interior), at, aux

    start = (jnp.full_like(centre, jnp.nan), jax.lax.stop_gradient(centre),
             stencil(jax.lax.stop_gradient(centre), interior), aux)
    return jax.lax.fori_loop(0, PEAK_NEWTON_STEPS, step, start)


def peak_frequencies(values: Float[Array, " freqs"], omegas: Float[Array, " freqs"], solve,
                     count: int):
    """The `count` highest local maxima of a response sampled as `values` on the grid
    `omegas` (`top_peaks`), each located in continuous frequency by `PEAK_NEWTON_STEPS`
    Newton steps (`newton_iterates`): `solve(at)` gives the response at a step's stencil
    frequencies `at` (peaks x points; no derivatives needed). Returns the grid indices,
    the last step's estimates, the frequencies of the peaks (a fixed point of the
    derivatives: the envelope theorem) and which are local maxima (band ends included).
    Each peak is the response at its frequency (`located_peak`)."""
    index, centre, valid = top_peaks(values, omegas, count)
    lower, upper, interior = bracket(index, omegas)
    estimate, centre, _, _ = newton_iterates(lambda at: (solve(at), ()), centre, interior,
                                             lower, upper)
    return index, estimate, jax.lax.stop_gradient(centre), valid


def true_peaks(values: Float[Array, " freqs"], omegas: Float[Array, " freqs"], solve,
               count: int):
    """The `count` highest local maxima of a response sampled as `values` on the grid
    `omegas`, located in continuous frequency (`peak_frequencies`): `solve(at, last)`
    gives the response at the frequencies `at` (peaks x points): for `last` False a
    step's stencil (no derivatives needed), for `last` True the last iterate (one point:
    the peak, with derivatives). Returns the grid indices, the peaks, their frequencies
    and which are local maxima (band ends included)."""
    index, estimate, centre, valid = peak_frequencies(
        values, omegas, lambda at: solve(at, False), count)
    peak = located_peak(estimate, solve(centre[:, None], True)[:, 0])
    return index, peak, centre, valid
