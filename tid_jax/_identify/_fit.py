"""The inerter device identified from test records by nonlinear least squares on its force.

A record is a test in which a rig imposes a displacement across the device and measures
the force (the paper's Figures 2-3). The models are nested, each adding one term of
`InerterDevice` to the one before:

- `ideal`: inertance and friction force (the paper's model);
- `damped`: + parasitic damping;
- `compliant`: + series stiffness;
- `backlash`: + backlash.

Each model is fitted by Levenberg-Marquardt (optimistix) on the residual force of all
records together, from the model before it (the first two are linear in their
parameters and start from their linear least-squares solution). The standard errors are
those of the linearised problem in the parameters themselves (a term fitted at zero has
one too), with the noise variance of each record estimated from its residual; the
comparison says which terms the data support by the Bayesian information criterion.
"""

import itertools
import math
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._model._checks import check_precision, choice, integer, is_positive, real_scalar
from .._optimise._stall import cut_within_tolerance
from .._runtime._cache import compiled
from .._runtime._parallel import serial
from ._device import ForceSettings, InerterDevice, Motion, device_force, friction_width

MODELS = ("ideal", "damped", "compliant", "backlash")
# each model the one before and one more term of `InerterDevice`
_TERMS = ("inertance", "friction_force", "parasitic_damping", "series_stiffness", "backlash")
MODEL_PARAMETERS = {model: _TERMS[: i + 2] for i, model in enumerate(MODELS)}
MIN_SAMPLES = 32
_NEGLIGIBLE = 1e-3  # a start below this fraction of its term's typical size is scaled by the latter


class InerterRecord(eqx.Module):
    """One test record (SI units): sample times (s, strictly increasing), the imposed
    displacement across the device (m) and the measured force (N)."""

    time: Float[Array, " samples"]
    displacement: Float[Array, " samples"]
    force: Float[Array, " samples"]
    name: str = eqx.field(static=True, default="")

    def __check_init__(self):
        where = f"record {self.name!r}" if self.name else "record"
        columns = {"time": self.time, "displacement": self.displacement, "force": self.force}
        arrays = {}
        for column, values in columns.items():
            array = np.asarray(values, dtype=float)
            if array.ndim != 1:
                raise ValueError(f"{where}: {column} must be 1-d, got shape {array.shape}")
            bad = ~np.isfinite(array)
            if np.any(bad):
                raise ValueError(f"{where}: {column} is not finite at sample "
                                 f"{int(np.argmax(bad))} ({array[np.argmax(bad)]!r})")
            arrays[column] = array
        lengths = {column: array.size for column, array in arrays.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"{where}: columns of different lengths {lengths}")
        if lengths["time"] < MIN_SAMPLES:
            raise ValueError(f"{where} is too short: {lengths['time']} samples, at least "
                             f"{MIN_SAMPLES} needed")
        steps = np.diff(arrays["time"])
        if np.any(steps <= 0):
            i = int(np.argmax(steps <= 0)) + 1
            raise ValueError(f"{where}: time must increase strictly; sample {i} "
                             f"({arrays['time'][i]!r} s) does not")
        if np.ptp(arrays["displacement"]) == 0:
            raise ValueError(f"{where}: the displacement does not move")


class ModelComparison(eqx.Module):
    """The nested models fitted, in order: their parameter counts, the residual RMS over
    all records (N), the Bayesian information criterion `n ln(RSS / n) + p ln n` and its
    change from the model before, and whether that change supports the model's added term
    (a fall of more than `IdentifySettings.support_bic`; the first model is supported by
    definition)."""

    models: tuple[str, ...] = eqx.field(static=True)
    parameter_counts: tuple[int, ...] = eqx.field(static=True)
    rms: Float[Array, " models"]
    bic: Float[Array, " models"]
    delta_bic: Float[Array, " models"]
    supported: Bool[Array, " models"]
    converged: Bool[Array, " models"]


class InerterFit(eqx.Module):
    """A device identified from records: `model`, the fitted `parameters` (names of
    `InerterDevice` fields) with their `estimates`, `standard_errors` and `correlations`
    (SI units), the `device` (the estimates and the terminal mass held, other fields at
    their defaults), the
    residual RMS per record (N), the fitted force of each record (N), whether the least
    squares converged (and every integration succeeded), its steps, and the comparison of
    the nested models up to this one."""

    model: str = eqx.field(static=True)
    parameters: tuple[str, ...] = eqx.field(static=True)
    device: InerterDevice
    estimates: Float[Array, " parameters"]
    standard_errors: Float[Array, " parameters"]
    correlations: Float[Array, "parameters parameters"]
    rms: Float[Array, " records"]
    fitted_force: tuple[Float[Array, " samples"], ...]
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    comparison: ModelComparison


class IdentifySettings(eqx.Module):
    """Settings of `identify_inerter`. Defaults live here only.

    - `rtol`, `atol`, `max_steps`: the least squares' tolerances (optimistix, on the
      scaled parameters and the force relative to the records' peak) and steps.
    - `force`: the device's `ForceSettings`.
    - `stiffness_starts`: starting values tried for the series stiffness, times its
      typical size (a resonance ten times the fastest test's frequency): the force of a
      compliant device rings after each reversal at a frequency set by the series
      stiffness, so that the least squares in it have many local minima. Empty: no scan.
    - `backlash_starts`: the same for the backlash, times 1% of the smallest stroke: the
      force rattles through the free play.
    - `starts_per_task`: starting values per task of the processes that share the scan.
    - `support_bic`: a model's added term is supported where it lowers the Bayesian
      information criterion by more than this.
    """

    rtol: float = 1e-9
    atol: float = 1e-9
    max_steps: int = 200
    force: ForceSettings = ForceSettings()
    stiffness_starts: tuple[float, ...] = tuple(float(v) for v in np.geomspace(2e-2, 1e2, 25))
    backlash_starts: tuple[float, ...] = tuple(float(v) for v in np.geomspace(0.1, 30, 7))
    starts_per_task: int = 8
    support_bic: float = 10.0

    def __check_init__(self):
        for name in ("stiffness_starts", "backlash_starts"):
            value = getattr(self, name)
            if not (isinstance(value, tuple) and all(is_positive(v) for v in value)):
                raise ValueError(f"IdentifySettings.{name} must be a tuple of positive "
                                 f"numbers, got {value!r}")
        integer("IdentifySettings.starts_per_task", self.starts_per_task, 1)
        if not (is_positive(self.support_bic) or self.support_bic == 0):
            raise ValueError("IdentifySettings.support_bic must be a number >= 0, got "
                             f"{self.support_bic!r}")

    def scanned_starts(self) -> dict[str, np.ndarray]:
        """The starting values scanned per term, times its typical size (the terms with
        any)."""
        starts = {"series_stiffness": self.stiffness_starts, "backlash": self.backlash_starts}
        return {name: np.asarray(values) for name, values in starts.items() if values}


_SQUARED = ("friction_force", "parasitic_damping")  # terms that are squares of unknowns


class _Scales(eqx.Module):
    """The map between the least-squares unknowns and the device's parameters: linear
    for the inertance, logarithmic for the series stiffness, the square for the friction
    force and the damping, the magnitude for the backlash. None is ever negative: where
    the records ask for less (as a model without a term they need may), that term fits
    at zero, which a squared unknown reaches smoothly."""

    parameters: tuple[str, ...] = eqx.field(static=True)
    scales: Float[Array, " parameters"]
    terminal_mass: Float[Array, ""]  # kg, known and held

    def device(self, x) -> InerterDevice:
        return self.device_of(self.values(x))

    def device_of(self, values) -> InerterDevice:
        """The device with its parameters at `values` (their own units)."""
        return InerterDevice(**dict(zip(self.parameters, values, strict=True)),
                             terminal_mass=self.terminal_mass)

    def values(self, x) -> Float[Array, " parameters"]:
        out = []
        for i, name in enumerate(self.parameters):
            if name == "series_stiffness":
                ratio = jnp.exp(x[i])
            elif name in _SQUARED:
                ratio = x[i] ** 2
            elif name == "backlash":
                ratio = jnp.abs(x[i])
            else:
                ratio = x[i]
            out.append(self.scales[i] * ratio)
        return jnp.stack(out)

    def unknowns(self, values) -> Float[Array, " parameters"]:
        out = []
        for i, name in enumerate(self.parameters):
            ratio = values[i] / self.scales[i]
            if name == "series_stiffness":
                ratio = jnp.log(ratio)
            elif name in _SQUARED:
                ratio = jnp.sqrt(jnp.abs(ratio))
            out.append(ratio)
        return jnp.stack(out)


def _records(records) -> tuple[InerterRecord, ...]:
    if isinstance(records, InerterRecord):
        records = (records,)
    if not isinstance(records, list | tuple) or not records:
        raise ValueError("records must be an InerterRecord or a non-empty list of them")
    for i, record in enumerate(records):
        if not isinstance(record, InerterRecord):
            raise ValueError(f"records[{i}] must be an InerterRecord, got "
                             f"{type(record).__name__}")
    return tuple(records)


def _residuals(x, scales: _Scales, motions, forces, force_scale, settings: ForceSettings):
    """The force residuals of every record, over `force_scale`, and whether every
    integration succeeded."""
    return _device_residuals(scales.device(x), motions, forces, force_scale, settings)


def _device_residuals(device: InerterDevice, motions, forces, force_scale,
                      settings: ForceSettings):
    """`_residuals` of `device`. The records of one length (and spacing) are integrated
    one after the other in a loop (`jax.lax.map`): a compiled program holds one copy of
    the mechanism's integration per kind of record, not one per record."""
    models, ok = [None] * len(motions), jnp.asarray(True)
    for group in _alike(motions):
        stacked = jax.tree.map(lambda *a: jnp.stack(a), *(motions[i] for i in group))
        model, success = jax.lax.map(lambda motion: device_force(device, motion, settings),
                                     stacked)
        ok = ok & jnp.all(success)
        for row, i in enumerate(group):
            models[i] = model[row]
    return jnp.concatenate([(model - force) / force_scale
                            for model, force in zip(models, forces, strict=True)]), ok


def _alike(motions) -> list[list[int]]:
    """The indices of `motions` grouped by their number of samples and whether they are
    evenly spaced, in order."""
    groups = {}
    for i, motion in enumerate(motions):
        groups.setdefault((motion.time.shape[0], motion.evenly_spaced), []).append(i)
    return list(groups.values())


class _LevenbergMarquardt(optx.LevenbergMarquardt):
    """`optx.LevenbergMarquardt` that also ends where a step was rejected and the next
    one is cut to a move within the tolerance (as an accepted step's is measured). At
    the optimum the residual's integration error (the mechanism's integration at
    `ForceSettings.rtol`) rejects the moves that would count, and the trust region would
    be cut on towards zero, a Jacobian of every record at each cut, until a move small
    enough to change no residual by more than the tolerance is accepted."""

    def terminate(self, fn, y, args, options, state, tags):
        done, result = super().terminate(fn, y, args, options, state, tags)
        settled = (state.num_steps_since_acceptance > 0) & cut_within_tolerance(self, y, state)
        return done | settled, result


@compiled
def _solve(x0, scales, motions, forces, force_scale, settings: ForceSettings, *, rtol, atol,
           max_steps):
    """Levenberg-Marquardt from the unknowns `x0` to the tolerances `rtol`, `atol` in at
    most `max_steps` steps, with `settings` the device's: the unknowns, the residual (N)
    and its Jacobian in the parameters themselves, success and the steps."""
    fn = lambda x, _: _residuals(x, scales, motions, forces, force_scale, settings)
    # the damped steps by Cholesky on the normal equations (few, well-scaled unknowns),
    # whose LAPACK call, unlike QR's, can be kept in the program cache
    solver = _LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(fn, solver, x0, has_aux=True, max_steps=max_steps, throw=False)
    x = sol.value

    # the Jacobian in the parameters themselves, for their covariance: defined where a
    # term is at its bound 0 too, where the unknowns' map (a square, a magnitude) is flat;
    # the residuals from the same integrations
    def residuals(values):
        residual, ok = _device_residuals(scales.device_of(values), motions, forces,
                                         force_scale, settings)
        return residual, (residual, ok)

    jacobian, (residual, ok) = jax.jacfwd(residuals, has_aux=True)(scales.values(x))
    return x, residual * force_scale, jacobian * force_scale, \
        ok & (sol.result == optx.RESULTS.successful), sol.stats["num_steps"]


def _linear_start(parameters, motions, forces, width):
    """Least-squares inertance, friction and damping of the rigid device (linear in
    them), for the first models' start; `forces` less the terminal mass's."""
    columns = {
        "inertance": lambda m: m.acceleration,
        "friction_force": lambda m: np.tanh(np.asarray(m.velocity) / width(m)),
        "parasitic_damping": lambda m: m.velocity,
    }
    matrix = np.concatenate(
        [np.stack([np.asarray(columns[name](m)) for name in parameters], axis=1)
         for m in motions])
    solution, *_ = np.linalg.lstsq(matrix, np.concatenate(forces), rcond=None)
    return solution


@compiled
def _sum_of_squares(x, scales, motions, forces, force_scale, settings: ForceSettings):
    residual, ok = _residuals(x, scales, motions, forces, force_scale, settings)
    return jnp.where(ok, jnp.sum(residual**2), jnp.inf)


def _scanned_start(parameters, values, motions, forces, force_scale,
                   settings: IdentifySettings, typical, stiffness_limit, terminal_mass,
                   map_lanes):
    """`values` with the scanned terms (`IdentifySettings.scanned_starts`) of the model at
    the best of their scanned starting values, tried together (a term fitted before also
    keeps its value as a candidate; no series stiffness above `stiffness_limit`), the
    others held; the candidates mapped `settings.starts_per_task` to a task by
    `map_lanes`."""
    starts = settings.scanned_starts()
    scanned = [name for name in parameters if name in starts]
    if not scanned:
        return values
    index = [parameters.index(name) for name in scanned]
    candidates = [np.unique(np.append(starts[name] * typical[name], values[i]))
                  for name, i in zip(scanned, index, strict=True)]
    # a series stiffness whose resonance the records cannot resolve is not tried
    candidates = [c[c <= stiffness_limit] if name == "series_stiffness" else c
                  for name, c in zip(scanned, candidates, strict=True)]
    if not all(c.size for c in candidates):
        return values  # none to try (records too coarse for any series stiffness)
    trials = np.repeat(values[None], math.prod(c.size for c in candidates), axis=0)
    trials[:, index] = list(itertools.product(*candidates))
    # the candidates mapped a few to a task
    task = settings.starts_per_task
    shared = jax.tree.map(np.asarray, (np.array([typical[name] for name in parameters]),
                                       terminal_mass, motions, forces, force_scale))
    costs = np.concatenate(map_lanes(_scan_costs, [
        (trials[start : start + task], parameters, *shared, settings.force)
        for start in range(0, len(trials), task)]))
    # the first of the lowest finite costs, in the product's order
    costs[~np.isfinite(costs)] = np.inf
    return trials[int(np.argmin(costs))] if np.isfinite(costs).any() else values


def _scan_costs(trials, parameters, typical, terminal_mass, motions, forces, force_scale,
                settings: ForceSettings):
    """The sum of squares at each of `trials` (parameter values, the unknowns scaled by
    their `typical` sizes): a task of `map_lanes` (NumPy arguments)."""
    (typical, terminal_mass, motions, forces, force_scale) = jax.tree.map(
        jnp.asarray, (typical, terminal_mass, motions, forces, force_scale))
    scales = _Scales(parameters, typical, terminal_mass)
    return np.array([float(_sum_of_squares(scales.unknowns(jnp.asarray(trial)), scales,
                                           motions, forces, force_scale, settings))
                     for trial in trials])


def _fit(model, start, motions, forces, force_scale, settings: IdentifySettings, typical,
         stiffness_limit, terminal_mass, map_lanes):
    """Least squares for `model` from the parameter values `start` (a dict; where a
    term is missing from it, the scanned terms start from a scan)."""
    parameters = MODEL_PARAMETERS[model]
    values = np.array([start.get(name, typical[name]) for name in parameters])
    if any(name not in start for name in parameters):
        values = _scanned_start(parameters, values, motions, forces, force_scale, settings,
                                typical, stiffness_limit, terminal_mass, map_lanes)
    # each unknown scaled by its start, or by its typical size where the start is (next
    # to) zero: a term a simpler model fitted at zero can grow again
    scales = np.array([abs(v) if abs(v) > _NEGLIGIBLE * typical[name] else typical[name]
                       for name, v in zip(parameters, values, strict=True)])
    scales = _Scales(parameters, jnp.asarray(scales), terminal_mass)
    x0 = scales.unknowns(jnp.asarray(values))
    x, residual, jacobian, ok, steps = _solve(
        x0, scales, motions, forces, force_scale, settings.force, rtol=settings.rtol,
        atol=settings.atol, max_steps=settings.max_steps)
    return scales, x, np.asarray(residual), np.asarray(jacobian), bool(ok), int(steps)


def _covariance(jacobian, pieces, p):
    """The covariance of the least-squares estimates (of the unknowns that `jacobian`
    differentiates: the residual's Jacobian) with the noise variance estimated
    per record (tests of different forces are measured with different noise):
    `(J^T J)^-1 J^T diag(s_r^2) J (J^T J)^-1`, `s_r^2` the mean square residual of
    record `r` times `n / (n - p)`."""
    n = jacobian.shape[0]
    variance = np.concatenate([np.full(piece.size, np.mean(piece**2)) for piece in pieces])
    variance = variance * n / max(n - p, 1)
    inverse = np.linalg.pinv(jacobian.T @ jacobian)
    return inverse @ (jacobian.T @ (variance[:, None] * jacobian)) @ inverse


def identify_inerter(records, *, model: str = "ideal", terminal_mass: float = 0.0,
                     settings: IdentifySettings = IdentifySettings(),
                     progress: Callable[[str], None] | None = None,
                     map_lanes: Callable = serial) -> InerterFit:
    """Identify the inerter device from test records; the nested models before `model`
    are fitted first and compared with it.

    **Arguments:**

    - `records`: an `InerterRecord` or a list of them (time s, imposed displacement m,
      measured force N).
    - `model`: one of `MODELS`: "ideal" (b, ff), "damped" (+ parasitic damping),
      "compliant" (+ series stiffness), "backlash" (+ free play).
    - `terminal_mass`: the device's moving mass at its driven terminal, kg, known from
      the device (weighed or from its drawings), held at this value in every model: the
      records cannot tell it from the inertance (of a rigid device not at all), and a
      compliant device's design needs it (`TIDSystem.terminal_mass`). With the default
      0, the inertance of a rigid model includes it.
    - `settings`: `IdentifySettings`.
    - `progress`: if given, called with a line as each model is fitted.
    - `map_lanes`: how the scan of starting values is mapped, a few candidates to a task
      (default: in this process; see `_parallel`).

    **Returns:** an `InerterFit` (SI units).
    """
    check_precision()
    choice("model", model, MODELS)
    real_scalar("terminal_mass", terminal_mass, "non-negative")
    integer("settings.max_steps", settings.max_steps, 1)
    records = _records(records)
    motions = [Motion.from_samples(r.time, r.displacement) for r in records]
    forces = [jnp.asarray(r.force, float) for r in records]
    peak_force = max(float(np.max(np.abs(f))) for f in forces)
    if peak_force == 0:
        raise ValueError("records: the force is zero throughout")
    force_scale = jnp.asarray(peak_force)  # an argument of the compiled programs, not a key
    held_mass = jnp.asarray(float(terminal_mass))
    # the forces less the terminal mass's, to which the rigid models' starts are linear
    mechanism_forces = [f - held_mass * m.acceleration
                        for f, m in zip(forces, motions, strict=True)]
    width = lambda m: float(friction_width(m, settings.force))
    typical, stiffness_limit = _typical_sizes(motions, mechanism_forces, peak_force, width)
    fits = []
    for name in MODELS[: MODELS.index(model) + 1]:
        parameters = MODEL_PARAMETERS[name]
        if name in ("ideal", "damped"):  # from their linear least squares
            start = dict(zip(parameters, _linear_start(parameters, motions, mechanism_forces,
                                                       width), strict=True))
        else:  # from the model before, its added term missing
            start = fits[-1].estimates()
        fits.append(_model_fit(name, start, motions, forces, force_scale, settings, typical,
                               stiffness_limit, held_mass, map_lanes))
        if progress is not None:
            progress(fits[-1].summary())
    return _inerter_fit(model, float(terminal_mass), forces, fits, settings.support_bic)


def _typical_sizes(motions, mechanism_forces, peak_force: float, width):
    """Typical sizes of the terms: the starting values of terms fitted afresh, and the
    scales of terms whose start is zero; and the largest series stiffness that the
    records resolve (a resonance at an eighth of the sampling rate)."""
    omega_max = max(math.sqrt(float(np.max(np.abs(m.acceleration)))
                              / float(np.max(np.abs(m.displacement)))) for m in motions)
    b0, ff0 = _linear_start(MODEL_PARAMETERS["ideal"], motions, mechanism_forces, width)
    b0 = abs(b0) if b0 != 0 else peak_force / float(np.max(np.abs(motions[0].acceleration)))
    typical = {
        "inertance": b0,
        "friction_force": max(abs(ff0), 1e-3 * peak_force),
        "parasitic_damping": peak_force / max(float(np.max(np.abs(m.velocity)))
                                               for m in motions),
        "series_stiffness": 100 * b0 * omega_max**2,  # a resonance 10x the fastest test's
        "backlash": 1e-2 * min(float(np.max(np.abs(m.displacement))) for m in motions),
    }
    stiffness_limit = b0 * (2 * math.pi / (8 * max(float(np.median(np.diff(m.time)))
                                                   for m in motions))) ** 2
    return typical, stiffness_limit


class _ModelFit(NamedTuple):
    """One nested model fitted: its parameters' values, standard errors and correlations
    (SI), the residual of each record (N), the residual sum of squares (N^2) over all the
    records' samples, whether the least squares converged and its steps."""

    name: str
    values: np.ndarray
    errors: np.ndarray
    correlations: np.ndarray
    pieces: list
    rss: float
    samples: int
    ok: bool
    steps: int

    def estimates(self) -> dict:
        """The fitted values by parameter name."""
        return dict(zip(MODEL_PARAMETERS[self.name], self.values, strict=True))

    def summary(self) -> str:
        return (f"model {self.name!r} fitted: residual RMS "
                f"{math.sqrt(self.rss / self.samples):.4g} N"
                f"{'' if self.ok else ' (not converged)'}")


def _model_fit(name, start, motions, forces, force_scale, settings: IdentifySettings,
               typical, stiffness_limit, held_mass, map_lanes) -> _ModelFit:
    """The model `name` fitted from `start` (`_fit`), with the standard errors of its
    estimates."""
    sizes = [f.shape[0] for f in forces]
    scales, x, residual, jacobian, ok, steps = _fit(
        name, start, motions, forces, force_scale, settings, typical, stiffness_limit,
        held_mass, map_lanes)
    values = np.asarray(scales.values(x))
    pieces = np.split(residual, np.cumsum(sizes)[:-1])
    # in units of each term's scale, where the Jacobian is well conditioned
    size = np.asarray(scales.scales)
    covariance = size[:, None] * _covariance(jacobian * size, pieces, len(values)) * size[None, :]
    errors = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlations = covariance / np.outer(errors, errors)
    return _ModelFit(name, values, errors, correlations, pieces,
                     float(np.sum(residual**2)), sum(sizes), ok, steps)


def _comparison(fits: list[_ModelFit], support_bic: float) -> ModelComparison:
    """The `ModelComparison` of the nested models `fits`, in order."""
    n = fits[0].samples
    counts = [len(fit.values) for fit in fits]
    bic = np.array([n * math.log(max(fit.rss, 1e-300) / n) + p * math.log(n)
                    for fit, p in zip(fits, counts, strict=True)])
    delta = np.concatenate([[0.0], np.diff(bic)])
    return ModelComparison(
        models=tuple(fit.name for fit in fits),
        parameter_counts=tuple(counts),
        rms=jnp.asarray([math.sqrt(fit.rss / n) for fit in fits]),
        bic=jnp.asarray(bic),
        delta_bic=jnp.asarray(delta),
        supported=jnp.asarray([True] + [bool(d < -support_bic) for d in delta[1:]]),
        converged=jnp.asarray([fit.ok for fit in fits]),
    )


def _inerter_fit(model, terminal_mass: float, forces, fits: list[_ModelFit],
                 support_bic: float) -> InerterFit:
    """The `InerterFit` of `model`, the last of the nested models `fits`."""
    last = fits[-1]
    fitted = tuple(jnp.asarray(f) + jnp.asarray(piece)
                   for f, piece in zip(forces, last.pieces, strict=True))
    return InerterFit(
        model=model,
        parameters=MODEL_PARAMETERS[model],
        device=InerterDevice(**dict(zip(MODEL_PARAMETERS[model],
                                        (float(v) for v in last.values), strict=True)),
                             terminal_mass=terminal_mass),
        estimates=jnp.asarray(last.values),
        standard_errors=jnp.asarray(last.errors),
        correlations=jnp.asarray(last.correlations),
        rms=jnp.asarray([math.sqrt(float(np.mean(piece**2))) for piece in last.pieces]),
        fitted_force=fitted,
        converged=jnp.asarray(last.ok),
        steps=jnp.asarray(last.steps),
        comparison=_comparison(fits, support_bic),
    )
