"""Design of tuned inerter dampers (TIDs) whose inerter has dry friction.

The public API is the names below, each from the module of its idea. They load when
first used: `import tid_jax` alone imports neither JAX nor equinox, so that an entry
point can set their environment first (the `tid-jax` command's `EQX_ON_ERROR`).
"""

import importlib

__version__ = "0.1.0"

_API = {
    "_band": ("Peaks", "default_omegas", "peak_response", "peaks"),
    "_best_tunings": ("BestTunings", "best_tunings"),
    "_building": ("BuildingTID", "Quantity", "as_building", "building_breakaway",
                  "first_mode_tunings", "linear_building_response"),
    "_building_design": ("BUILDING_BAND", "BuildingRetune", "building_peaks",
                         "retune_building"),
    "_building_orbit": ("BuildingResponse", "building_response"),
    "_building_robust": ("BuildingRobust", "robust_building"),
    "_building_sensitivity": ("BuildingOptimum", "BuildingSensitivities",
                              "building_sensitivities"),
    "_cache": ("enable_compilation_cache",),
    "_cache_folder": ("default_cache_dir",),
    "_device": ("ForceSettings", "InerterDevice"),
    "_identify": ("IdentifySettings", "InerterFit", "InerterRecord", "ModelComparison",
                  "identify_inerter"),
    "_monte_carlo": ("MonteCarlo", "MonteCarloSettings", "friction_history", "monte_carlo",
                     "random_history"),
    "_parallel": ("ProcessMap",),
    "_linear": ("Breakaway", "LinearReceptance", "breakaway_amplitude", "den_hartog",
                "den_hartog_tuning", "linear_receptance", "paper_system", "stuck_receptance"),
    "_response": ("FrequencyResponse", "frequency_response"),
    "_retune": ("RetuneResult", "RetuneSettings", "retune"),
    "_robust": ("RobustDesign", "RobustSettings", "TuningPerformance", "robust_tune",
                "tuning_performance"),
    "_sensitivity": ("OptimumSensitivities", "SensitivitySettings", "Sensitivities",
                     "amplitude_sensitivities", "sensitivities"),
    "_settings": ("SolverSettings",),
    "_random_design": ("LinearisationOutcome", "RandomDesign", "RandomSensitivities",
                       "default_bounds", "random_sensitivities", "retune_random"),
    "_record_design": ("RecordDesign", "design_for_records"),
    "_records": ("GroundMotion", "History", "jennings_envelope", "linear_history", "read_at2",
                 "read_csv_record", "synthetic_motion"),
    "_stationary": ("Linearisation", "StationaryLoad", "h2_tuning", "rms_response",
                    "stationary_covariance", "statistical_linearisation"),
    "_structure": ("Structure",),
    "_substructuring": ("Substructuring", "SubstructuringStability",
                        "simulate_substructuring", "substructuring_stability"),
    "_system": ("DEFAULT_FRICTION_WIDTH", "PAPER_AMPLITUDES", "PAPER_STROKE", "TIDSystem"),
}
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
