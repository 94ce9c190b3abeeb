"""Design of tuned inerter dampers (TIDs) whose inerter has dry friction.

The public API is the names below, each from the module of its idea. They load when
first used: `import tid_jax` alone imports neither JAX nor equinox, so that an entry
point can set their environment first (the `tid-jax` command's `EQX_ON_ERROR`).
"""

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

_API = {
    "_identify._device": ("ForceSettings", "InerterDevice"),
    "_identify._fit": ("IdentifySettings", "InerterFit", "InerterRecord", "ModelComparison",
                       "identify_inerter"),
    "_loads._monte_carlo": ("MonteCarlo", "MonteCarloSettings", "friction_history", "monte_carlo",
                            "random_history"),
    "_loads._random_design": ("RandomDesign", "RandomSensitivities", "default_bounds",
                              "random_sensitivities", "retune_random"),
    "_loads._record_design": ("RecordDesign", "design_for_records"),
    "_loads._records": ("GroundMotion", "History", "jennings_envelope", "linear_history",
                        "read_at2", "read_csv_record", "synthetic_motion"),
    "_loads._stationary": ("Linearisation", "StationaryLoad", "h2_tuning", "rms_response",
                           "stationary_covariance", "statistical_linearisation"),
    "_model._building": ("BuildingTID", "Quantity", "as_building", "first_mode_tunings"),
    "_model._linear": ("Breakaway", "LinearReceptance", "den_hartog", "den_hartog_tuning",
                       "paper_system", "stuck_receptance"),
    "_model._structure": ("Structure",),
    "_model._system": ("DEFAULT_FRICTION_WIDTH", "PAPER_AMPLITUDES", "PAPER_STROKE", "TIDSystem"),
    "_optimise._best_tunings": ("BestTunings", "best_tunings"),
    "_orbit._settings": ("SolverSettings",),
    "_peaks": ("Peaks", "default_omegas", "peak_response", "peaks"),
    "_receptance": ("breakaway_amplitude", "linear_receptance"),
    "_response": ("FrequencyResponse", "frequency_response"),
    "_retune": ("RetuneResult", "RetuneSettings", "retune"),
    "_robust": ("RobustDesign", "RobustSettings", "TuningPerformance", "robust_tune",
                "tuning_performance"),
    "_runtime._cache": ("enable_compilation_cache",),
    "_runtime._cache_folder": ("default_cache_dir",),
    "_runtime._outcomes": ("Outcome",),
    "_runtime._parallel": ("ProcessMap",),
    "_sensitivity": ("OptimumSensitivities", "SensitivitySettings", "Sensitivities",
                     "amplitude_sensitivities", "sensitivities"),
    "_substructuring._simulate": ("Substructuring", "SubstructuringStability",
                                  "simulate_substructuring", "substructuring_stability"),
}
if TYPE_CHECKING:  # the names as IDEs and type checkers see them; loaded lazily below
    from ._identify._device import (
        ForceSettings as ForceSettings,
        InerterDevice as InerterDevice,
    )
    from ._identify._fit import (
        IdentifySettings as IdentifySettings,
        InerterFit as InerterFit,
        InerterRecord as InerterRecord,
        ModelComparison as ModelComparison,
        identify_inerter as identify_inerter,
    )
    from ._loads._monte_carlo import (
        MonteCarlo as MonteCarlo,
        MonteCarloSettings as MonteCarloSettings,
        friction_history as friction_history,
        monte_carlo as monte_carlo,
        random_history as random_history,
    )
    from ._loads._random_design import (
        RandomDesign as RandomDesign,
        RandomSensitivities as RandomSensitivities,
        default_bounds as default_bounds,
        random_sensitivities as random_sensitivities,
        retune_random as retune_random,
    )
    from ._loads._record_design import (
        RecordDesign as RecordDesign,
        design_for_records as design_for_records,
    )
    from ._loads._records import (
        GroundMotion as GroundMotion,
        History as History,
        jennings_envelope as jennings_envelope,
        linear_history as linear_history,
        read_at2 as read_at2,
        read_csv_record as read_csv_record,
        synthetic_motion as synthetic_motion,
    )
    from ._loads._stationary import (
        Linearisation as Linearisation,
        StationaryLoad as StationaryLoad,
        h2_tuning as h2_tuning,
        rms_response as rms_response,
        stationary_covariance as stationary_covariance,
        statistical_linearisation as statistical_linearisation,
    )
    from ._model._building import (
        BuildingTID as BuildingTID,
        Quantity as Quantity,
        as_building as as_building,
        first_mode_tunings as first_mode_tunings,
    )
    from ._model._linear import (
        Breakaway as Breakaway,
        LinearReceptance as LinearReceptance,
        den_hartog as den_hartog,
        den_hartog_tuning as den_hartog_tuning,
        paper_system as paper_system,
        stuck_receptance as stuck_receptance,
    )
    from ._model._structure import (
        Structure as Structure,
    )
    from ._model._system import (
        DEFAULT_FRICTION_WIDTH as DEFAULT_FRICTION_WIDTH,
        PAPER_AMPLITUDES as PAPER_AMPLITUDES,
        PAPER_STROKE as PAPER_STROKE,
        TIDSystem as TIDSystem,
    )
    from ._optimise._best_tunings import (
        BestTunings as BestTunings,
        best_tunings as best_tunings,
    )
    from ._orbit._settings import (
        SolverSettings as SolverSettings,
    )
    from ._peaks import (
        Peaks as Peaks,
        default_omegas as default_omegas,
        peak_response as peak_response,
        peaks as peaks,
    )
    from ._receptance import (
        breakaway_amplitude as breakaway_amplitude,
        linear_receptance as linear_receptance,
    )
    from ._response import (
        FrequencyResponse as FrequencyResponse,
        frequency_response as frequency_response,
    )
    from ._retune import (
        RetuneResult as RetuneResult,
        RetuneSettings as RetuneSettings,
        retune as retune,
    )
    from ._robust import (
        RobustDesign as RobustDesign,
        RobustSettings as RobustSettings,
        TuningPerformance as TuningPerformance,
        robust_tune as robust_tune,
        tuning_performance as tuning_performance,
    )
    from ._runtime._cache import (
        enable_compilation_cache as enable_compilation_cache,
    )
    from ._runtime._cache_folder import (
        default_cache_dir as default_cache_dir,
    )
    from ._runtime._outcomes import (
        Outcome as Outcome,
    )
    from ._runtime._parallel import (
        ProcessMap as ProcessMap,
    )
    from ._sensitivity import (
        OptimumSensitivities as OptimumSensitivities,
        Sensitivities as Sensitivities,
        SensitivitySettings as SensitivitySettings,
        amplitude_sensitivities as amplitude_sensitivities,
        sensitivities as sensitivities,
    )
    from ._substructuring._simulate import (
        Substructuring as Substructuring,
        SubstructuringStability as SubstructuringStability,
        simulate_substructuring as simulate_substructuring,
        substructuring_stability as substructuring_stability,
    )

_MODULE_OF = {name: module for module, names in _API.items() for name in names}
__all__ = sorted(_MODULE_OF)


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
