"""The numerical settings of the steady-state solver, with their defaults."""

import functools as ft
from typing import NamedTuple

import equinox as eqx
import numpy as np

from .._model._checks import is_positive

# The settings that `SolverSettings.with_array_tolerances` makes arrays (`coarse_rtol`
# last).
_ARRAY_FIELDS = ("rtol", "atol", "max_newton_steps", "coarse_residual", "chord_residual",
                 "periodicity_tol", "exact_periodicity_tol", "coarse_rtol")


def _is_number(value) -> bool:
    return isinstance(value, int | float)


class SolverSettings(eqx.Module):
    """Numerical settings of the steady-state (shooting) solver. Defaults live here only.

    - `rtol`, `atol`: tolerances of the adaptive integration, on the state scaled by the
      static displacement A / K.
    - `implicit`: the integrator of smoothed friction: True, the implicit Kvaerno5; False,
      the explicit Tsit5; None (automatic), Kvaerno5 where the explicit steps a period
      needs for stability (estimated at each point's linear equivalent start:
      `_stiffness`) exceed `_stiffness.STIFF_STEPS` at most of the points of a
      `frequency_response` call, as where a narrow friction width holds the device
      stuck, else Tsit5 (and where no points are given, as in the building designs).
    - `max_steps`: integration steps allowed per forcing period.
    - `transient_periods`: periods integrated from the initial guess (the linear steady
      state) before shooting; 0: Newton's iterations start from it.
    - `max_newton_steps`: Newton iterations allowed (in a batch, as many in each of its
      three stages below).
    - `coarse_rtol`, `coarse_residual`: in a batch of steady states, the transient and
      the Newton iterations integrate at rtol `coarse_rtol` (atol in proportion; never
      more tightly than at `rtol`) until the periodicity residual is within
      `coarse_residual` (scaled): far from the orbit, a coarse period map takes the
      state as far per iteration at a fraction of the cost. Newton's iterations at
      `rtol` follow until the residual is within `chord_residual`, and their last
      monodromy matrix is the one reported.
    - `chord_residual`: from there, chord iterations (the last Newton matrix held) take
      the state to the orbit, each one integration without the variational equations,
      which also samples the orbit and verifies its periodicity.
    - `periodicity_tol`: a point counts as converged only if |Phi_T(z0) - z0| is below this
      (scaled), checked by the integration that samples the final orbit (smoothed friction;
      exact friction takes `exact_periodicity_tol`).
    - `samples`: points per period at which x and y are sampled; each peak is refined by a
      parabola through the three samples around it.
    - `exact_friction`: the exact Coulomb friction of a system with `friction_width=0`
      (the stick-slip flow of `_flow`, in closed form between transitions; `rtol`,
      `atol`, `max_steps` and `implicit` then play no part, and the samples also serve
      to find the transitions). The entry points set it from the system
      (`for_system`).
    - `exact_periodicity_tol`: the `periodicity_tol` of exact friction, whose period map
      has no integration error: Newton's iterations reach it in about one more step,
      and it keeps the stroke of a terminal that sticks for most of the period (a small
      difference of positions) accurate.
    - `compliant`: the six states of a compliant device (a finite `series_stiffness`):
      set from the system by the entry points (`for_system`).
    - `chunk`: points solved together as one vmapped batch (per device); larger batches
      are solved chunk after chunk, so that each chunk's adaptive integrations and
      Newton iterations wait only for its own slowest point (neighbouring points, of
      similar stiffness, share a chunk).
    """

    rtol: float = 1e-8
    atol: float = 1e-8
    max_steps: int = 4096
    transient_periods: int = 0
    max_newton_steps: int = 10
    coarse_rtol: float = 1e-6
    coarse_residual: float = 1e-2
    chord_residual: float = 1e-4
    periodicity_tol: float = 1e-6
    exact_periodicity_tol: float = 1e-10
    samples: int = 128
    implicit: bool | None = None
    exact_friction: bool = False
    compliant: bool = False
    chunk: int = 64

    def __check_init__(self):
        for name in ("rtol", "atol", "periodicity_tol", "exact_periodicity_tol", "coarse_rtol",
                     "coarse_residual", "chord_residual"):
            value = getattr(self, name)
            if not is_positive(value):
                raise ValueError(f"SolverSettings.{name} must be a positive number, got {value!r}")
        for name, low in (("max_steps", 16), ("transient_periods", 0), ("max_newton_steps", 1),
                          ("samples", 8), ("chunk", 1)):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= low):
                raise ValueError(
                    f"SolverSettings.{name} must be an integer >= {low}, got {value!r}")
        if not (self.implicit is None or isinstance(self.implicit, bool)):
            raise ValueError("SolverSettings.implicit must be None (automatic), True or False, "
                             f"got {self.implicit!r}")

    def with_implicit(self, stiff: bool) -> "SolverSettings":
        """These settings with `implicit` set to `stiff` where it is None (automatic)."""
        if self.implicit is not None:
            return self
        return eqx.tree_at(lambda s: s.implicit, self, stiff, is_leaf=lambda x: x is None)

    def fallbacks(self) -> tuple["SolverSettings", ...]:
        """Settings for further attempts, in turn, at points that did not converge: a
        long transient towards the attracting orbit, then more Newton iterations, first on
        integrations 100 times more accurate (Newton stalls where the integration error of
        the period map exceeds `periodicity_tol`), then with the implicit Kvaerno5 (stiff
        friction makes an explicit integration run out of steps); none coarse. Exact
        friction (these settings fitted to the system: `for_system`) has neither an
        integration error nor stiff steps: one attempt, the long transient and the more
        Newton iterations (the others would repeat its computation)."""
        persistent = eqx.tree_at(
            lambda s: (s.transient_periods, s.max_newton_steps),
            self,
            (max(40, 4 * self.transient_periods), max(25, 2 * self.max_newton_steps)),
        )
        if self.exact_friction:
            return (persistent.without_coarse(),)
        stiff = eqx.tree_at(lambda s: s.implicit, persistent.more_accurate(10), True,
                            is_leaf=lambda x: x is None)
        return persistent.more_accurate(100).without_coarse(), stiff.without_coarse()

    def more_accurate(self, factor: float = 100.0) -> "SolverSettings":
        """These settings integrating `factor` times more accurately (`rtol`, `atol`): for
        Newton's iterations that stall where the integration error of the period map
        exceeds `periodicity_tol`."""
        return eqx.tree_at(lambda s: (s.rtol, s.atol), self,
                           (self.rtol / factor, self.atol / factor))

    def coarse(self) -> "SolverSettings":
        """These settings with the coarse integration tolerances (`coarse_rtol`, atol in
        proportion), or the settings themselves where they are as coarse already (or
        `coarse_rtol` is None: `with_array_tolerances`), and for exact friction (whose
        period map has no integration error): a batch then has no coarse Newton
        iterations (`_steady_state.shoot_queue`)."""
        if self.exact_friction or self.coarse_rtol is None:
            return self
        if _is_number(self.rtol) and _is_number(self.coarse_rtol) and \
                self.coarse_rtol <= self.rtol:
            return self
        ratio = self.coarse_rtol / self.rtol
        return eqx.tree_at(lambda s: (s.rtol, s.atol), self, (self.coarse_rtol, self.atol * ratio))

    def tighter(self, factor: float) -> "SolverSettings":
        """These settings with `rtol`, `atol` and `periodicity_tol` `factor` times tighter;
        exact friction, whose period map has no integration error, keeps its own."""
        if self.exact_friction:
            return self
        return eqx.tree_at(lambda s: s.periodicity_tol, self.more_accurate(factor),
                           self.periodicity_tol / factor)

    def with_array_tolerances(self, system) -> "SolverSettings":
        """These settings as the compiled programs take them: fitted to the model of
        `system` (`for_system`), so that settings given fitted or not share a program,
        with their tolerances and Newton iterations as NumPy arrays, the programs'
        arguments, so that one program serves any of their values (the tighter settings
        of a polish, say); `coarse_rtol` None where there are no coarse Newton iterations
        (`coarse`). Equal settings for equal models give the same object (made once: the
        entry points ask for it on every call)."""
        model = _Model(system.compliant, system.exact_friction)
        try:
            return _with_array_tolerances(self, model)
        except TypeError:  # (unhashable: some of them arrays already)
            return _with_array_tolerances.__wrapped__(self, model)

    def without_coarse(self) -> "SolverSettings":
        """These settings with every Newton iteration of a batch at `rtol`."""
        return eqx.tree_at(lambda s: s.coarse_rtol, self, self.rtol)

    def to_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    @property
    def states(self) -> int:
        """The states of the scaled model: x, x', y, y', and a compliant device's
        mechanism q, q'."""
        return 6 if self.compliant else 4

    def for_system(self, system) -> "SolverSettings":
        """These settings with the model of `system` (a `TIDSystem` or a `BuildingTID`):
        exact Coulomb friction where its `friction_width` is 0, a compliant device's
        mechanism."""
        if self.compliant != system.compliant:
            self = eqx.tree_at(lambda s: s.compliant, self, system.compliant)
        if self.exact_friction == system.exact_friction:
            return self
        if not system.exact_friction:
            raise ValueError(
                "SolverSettings.exact_friction follows the system (friction_width=0); got "
                "exact_friction=True with a smoothed-friction system"
            )
        return eqx.tree_at(lambda s: (s.exact_friction, s.periodicity_tol), self,
                           (True, self.exact_periodicity_tol))


class _Model(NamedTuple):
    """What `SolverSettings.for_system` reads of a system."""

    compliant: bool
    exact_friction: bool


@ft.lru_cache(maxsize=64)
def _with_array_tolerances(settings: SolverSettings, model: _Model) -> SolverSettings:
    settings = settings.for_system(model)
    coarse = settings.coarse() is not settings
    names = _ARRAY_FIELDS if coarse else _ARRAY_FIELDS[:-1]
    out = eqx.tree_at(lambda s: tuple(getattr(s, name) for name in names), settings,
                      tuple(np.asarray(getattr(settings, name)) for name in names))
    return out if coarse else eqx.tree_at(lambda s: s.coarse_rtol, out, None)
