import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

PAPER_HOST_MASS = 1500.0  # kg
PAPER_HOST_FREQUENCY_HZ = 4.0  # Hz
PAPER_HOST_DAMPING_RATIO = 0.02
PAPER_INERTANCE = 75.0  # kg
PAPER_FRICTION_FORCE = 20.0  # N
PAPER_AMPLITUDES = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0, 900.0, 1000.0,
                    1500.0, 3000.0)  # N
PAPER_STROKE = 0.07  # m, inerter stroke limit (+-)
# The relative friction width (`friction_width=None`, the default of a compliant device),
# per forcing point:
# this ratio times the velocity amplitude omega A / K of the static displacement
# (`TIDSystem.width_at`).
FRICTION_WIDTH_RATIO = 0.02


class _DefaultWidth:
    """The default `friction_width`: exact Coulomb friction (0) for a rigid device, the
    relative width (None) for a compliant one, whose solver needs the friction smoothed."""

    def __repr__(self):
        return "DEFAULT_FRICTION_WIDTH"


DEFAULT_FRICTION_WIDTH = _DefaultWidth()

# (field name, allowed) with allowed "positive" (> 0) or "non-negative" (>= 0).
_FIELD_RULES = (
    ("host_mass", "positive"),
    ("host_stiffness", "positive"),
    ("host_damping", "non-negative"),
    ("inertance", "positive"),
    ("friction_force", "non-negative"),
    ("tid_stiffness", "positive"),
    ("tid_damping", "non-negative"),
    ("friction_width", "non-negative or None"),
    ("parasitic_damping", "non-negative"),
    ("terminal_mass", "non-negative"),
    ("series_stiffness", "positive or inf"),
    ("backlash", "non-negative"),
)
FIELD_NAMES = tuple(name for name, _ in _FIELD_RULES)
# The inerter's terms beyond inertance and friction (`TIDSystem`), with their defaults:
# the paper's ideal device.
DEVICE_TERMS = {"parasitic_damping": 0.0, "terminal_mass": 0.0, "series_stiffness": math.inf,
                "backlash": 0.0}


def check_values(name: str, value, allowed: str) -> None:
    """Raise `ValueError` naming `name` unless every entry of a concrete `value` is finite
    and `allowed` ("positive" or "non-negative"), or where `allowed` is "positive or
    inf", positive (infinity included). Traced values are not checked."""
    if isinstance(value, jax.core.Tracer):
        return
    array = np.asarray(value)
    if array.dtype == object or not np.issubdtype(array.dtype, np.number):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    if np.iscomplexobj(array):
        raise ValueError(f"{name} must be real, got {value!r}")
    if array.size == 0:
        raise ValueError(f"{name} must not be empty")
    if allowed == "positive or inf":
        bad = ~(array > 0)
        if np.any(bad):
            first = array.reshape(-1)[np.argmax(bad.reshape(-1))]
            raise ValueError(f"{name} must be positive (inf: rigid), got {float(first)!r}")
        return
    bad = ~np.isfinite(array)
    if allowed == "positive":
        bad |= ~(array > 0)
    elif allowed == "non-negative":
        bad |= ~(array >= 0)
    if np.any(bad):
        first = array.reshape(-1)[np.argmax(bad.reshape(-1))]
        raise ValueError(f"{name} must be finite and {allowed}, got {float(first)!r}")


def _as_float_array(name: str, value, allowed: str) -> Array:
    if isinstance(value, jax.core.Tracer):
        return value
    check_values(name, value, allowed)
    # One dtype (not weakly typed) whatever the value given: a Python float, a NumPy
    # scalar, an integer. The compiled programs that take a system are keyed by its
    # arrays' types, so that systems made either way share them.
    return jnp.asarray(value, dtype=jnp.result_type(float))


def is_compliant(stiffness) -> bool:
    """Whether a `series_stiffness` makes the device compliant (finite, or traced); one
    that mixes finite and infinite entries is an error."""
    if isinstance(stiffness, jax.core.Tracer):
        return True
    finite = np.isfinite(np.asarray(stiffness, dtype=float))
    if np.any(finite) and not np.all(finite):
        raise ValueError("series_stiffness must be finite everywhere or infinite (rigid) "
                         f"everywhere, got {np.asarray(stiffness).tolist()!r}")
    return bool(np.all(finite))


def _is_exact(width) -> bool:
    """Whether a `friction_width` selects exact Coulomb friction (all zero); a width that
    mixes zero and positive entries is an error."""
    if width is None or isinstance(width, jax.core.Tracer):
        return False
    try:
        zero = np.asarray(width, dtype=float) == 0
    except (TypeError, ValueError):
        return False  # not a number: the field's check names the problem
    if np.any(zero) and not np.all(zero):
        raise ValueError(
            "friction_width must be 0 (exact Coulomb friction) everywhere or positive "
            f"everywhere, got {np.asarray(width).tolist()}"
        )
    return bool(np.all(zero))


class TIDSystem(eqx.Module):
    """A single-degree-of-freedom host with a tuned inerter damper (TID), eq. (12):

        M x'' + C x' + K x + c (x' - y') + k (x - y) = A sin(w t)
        b y'' + c (y' - x') + k (y - x) + ff sgn(y') = 0

    with the inerter's dry friction `sgn` smoothed as `tanh(y' / width)`, or exact (with
    sticking) where `friction_width` is 0. The inerter's own parasitic damping `cp` and
    the moving mass `mt` at its terminal make the second equation

        (b + mt) y'' + cp y' + c (y' - x') + k (y - x) + ff sgn(y') = 0.

    **Fields** (SI units):

    - `host_mass`: M, kg.
    - `host_stiffness`: K, N/m.
    - `host_damping`: C, N s/m.
    - `inertance`: b, kg.
    - `friction_force`: ff, N (0 gives the ideal linear TID).
    - `tid_stiffness`: k, N/m.
    - `tid_damping`: c, N s/m.
    - `friction_width`: 0 for exact Coulomb friction (the default for a rigid device), the
      velocity scale `width` of the smoothed sign, m/s, or `None` (the default for a
      compliant device) to take it relative to each forcing point's motion:
      `FRICTION_WIDTH_RATIO` (0.02) times omega A / K, the velocity amplitude of the
      static displacement (`width_at`). Over structures of 0.1-10 Hz and 1e2-1e7 kg,
      mass ratios 0.005-0.2, any tuning and friction up to 0.6 A, the relative width
      keeps the peak host displacement within 0.35% of exact Coulomb friction (the
      inerter's within about 6%), where a fixed 1e-4 m/s, which smooths away most of the
      friction of slow, small-motion structures, errs by up to 48%.
    """

    host_mass: Float[Array, ""]
    host_stiffness: Float[Array, ""]
    host_damping: Float[Array, ""]
    inertance: Float[Array, ""]
    friction_force: Float[Array, ""]
    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    friction_width: Float[Array, ""] | None
    parasitic_damping: Float[Array, ""]
    terminal_mass: Float[Array, ""]
    series_stiffness: Float[Array, ""]
    backlash: Float[Array, ""]
    exact_friction: bool = eqx.field(static=True)
    compliant: bool = eqx.field(static=True)

    def __init__(
        self,
        host_mass: ArrayLike,
        host_stiffness: ArrayLike,
        host_damping: ArrayLike,
        inertance: ArrayLike,
        friction_force: ArrayLike,
        tid_stiffness: ArrayLike,
        tid_damping: ArrayLike,
        friction_width: ArrayLike | None = DEFAULT_FRICTION_WIDTH,
        *,
        parasitic_damping: ArrayLike = 0.0,
        terminal_mass: ArrayLike = 0.0,
        series_stiffness: ArrayLike | None = math.inf,
        backlash: ArrayLike = 0.0,
    ):
        values = locals()
        if series_stiffness is None:
            values["series_stiffness"] = math.inf
        # decided on the value given: arrays made here are traced inside `jax.jit`
        self.compliant = is_compliant(values["series_stiffness"])
        if friction_width is DEFAULT_FRICTION_WIDTH:
            values["friction_width"] = None if self.compliant else 0.0
        self.exact_friction = _is_exact(values["friction_width"])
        for name, allowed in _FIELD_RULES:
            value = values[name]
            if allowed == "non-negative or None":
                setattr(self, name,
                        None if value is None else _as_float_array(name, value, "non-negative"))
            else:
                setattr(self, name, _as_float_array(name, value, allowed))
        backlash = self.backlash
        if (not isinstance(backlash, jax.core.Tracer) and np.any(np.asarray(backlash) > 0)
                and self.rigid):
            raise ValueError("backlash needs a finite series_stiffness (a rigid device with "
                             "free play would impact)")

    @property
    def rigid(self) -> bool:
        """Whether the inerter is rigid: an infinite `series_stiffness` (decided on the
        value given; a traced one counts as finite)."""
        return not self.compliant

    @property
    def mass_ratio(self) -> Float[Array, ""]:
        """mu = b / M."""
        return self.inertance / self.host_mass

    @property
    def floors(self) -> int:
        """One: the host is a one-storey building."""
        return 1

    @property
    def host_frequency(self) -> Float[Array, ""]:
        """Undamped host natural frequency sqrt(K / M), rad/s."""
        return jnp.sqrt(self.host_stiffness / self.host_mass)

    def static_displacement(self, amplitude: ArrayLike) -> Float[Array, "..."]:
        """A / K, metres: the normalisation used for every response in the paper."""
        return jnp.asarray(amplitude) / self.host_stiffness

    def width_at(self, amplitude: ArrayLike, omega: ArrayLike) -> Float[Array, "..."]:
        """The friction width (m/s) used at forcing amplitude `amplitude` (N) and
        frequency `omega` (rad/s): `friction_width`, or where it is `None`,
        `FRICTION_WIDTH_RATIO` times omega A / K."""
        if self.friction_width is not None:
            return self.friction_width
        return FRICTION_WIDTH_RATIO * jnp.asarray(omega) * amplitude / self.host_stiffness

    def replace(self, **changes) -> "TIDSystem":
        """A copy with some fields changed (validated like the constructor). Exact
        friction that is not changed stays exact while the device stays rigid, and becomes
        the relative width (the default) where a change makes it compliant."""
        unknown = sorted(set(changes) - set(FIELD_NAMES))
        if unknown:
            raise ValueError(
                f"unknown TIDSystem field(s) {unknown}; fields are {list(FIELD_NAMES)}")
        values = {name: getattr(self, name) for name in FIELD_NAMES}
        if self.rigid:
            values["series_stiffness"] = math.inf  # the model, even where it is traced
        if self.exact_friction:
            # the model, even where the width is traced
            values["friction_width"] = DEFAULT_FRICTION_WIDTH if self.rigid else 0.0
        values.update(changes)
        return TIDSystem(**values)

    def to_dict(self) -> dict[str, float | None]:
        """Fields as plain Python floats (for JSON/TOML; `friction_width` None for the
        relative width, `series_stiffness` None for a rigid device); requires scalar
        fields."""
        values = {
            name: None if getattr(self, name) is None else float(np.asarray(getattr(self, name)))
            for name in FIELD_NAMES
        }
        if self.rigid:
            values["series_stiffness"] = None
        return values


def compiler_options(*args, **kwargs) -> dict:
    """XLA's options for a program compiled for these arguments (`_cache.compiled`):
    where they hold a system with exact Coulomb friction or a compliant device, XLA's
    fusion emitters off. Exact friction's period map is the closed-form stick-slip flow
    (`_flow`), whose programs compile in about two thirds of the time without them and
    run as fast. The compliant device's six-state integrations run faster without them:
    on the paper's system with a compliant device, its frequency response takes three
    quarters of the time (a third with backlash) and its sensitivities a quarter, their
    programs compiled in half the time. The rigid device's integrations of smoothed
    friction run about a third slower without them, and keep XLA's defaults (an empty
    dict)."""
    # (a `TIDSystem` or a `BuildingTID`: any model with both flags)
    is_model = lambda x: hasattr(x, "exact_friction") and hasattr(x, "compliant")
    systems = [leaf for leaf in jax.tree.leaves((args, kwargs), is_leaf=is_model)
               if is_model(leaf)]
    if any(system.exact_friction or system.compliant for system in systems):
        return {"xla_cpu_use_fusion_emitters": False}
    return {}
