"""Design of tuned inerter dampers (TIDs) whose inerter has dry friction."""

from ._cache import (
    default_cache_dir as default_cache_dir,
    enable_compilation_cache as enable_compilation_cache,
)
from ._linear import (
    Breakaway as Breakaway,
    breakaway_amplitude as breakaway_amplitude,
    LinearReceptance as LinearReceptance,
    den_hartog as den_hartog,
    den_hartog_tuning as den_hartog_tuning,
    linear_receptance as linear_receptance,
    paper_system as paper_system,
    stuck_receptance as stuck_receptance,
)
from ._response import (
    FrequencyResponse as FrequencyResponse,
    frequency_response as frequency_response,
)
from ._band import (
    Peaks as Peaks,
    default_omegas as default_omegas,
    peak_response as peak_response,
    peaks as peaks,
)
from ._retune import (
    RetuneResult as RetuneResult,
    RetuneSettings as RetuneSettings,
    retune as retune,
)
from ._design import (
    BestTunings as BestTunings,
    best_tunings as best_tunings,
)
from ._robust import (
    RobustDesign as RobustDesign,
    TuningPerformance as TuningPerformance,
    robust_tune as robust_tune,
    tuning_performance as tuning_performance,
)
from ._sensitivity import (
    OptimumSensitivities as OptimumSensitivities,
    Sensitivities as Sensitivities,
    sensitivities as sensitivities,
)
from ._device import (
    ForceSettings as ForceSettings,
    InerterDevice as InerterDevice,
)
from ._identify import (
    IdentifySettings as IdentifySettings,
    InerterFit as InerterFit,
    InerterRecord as InerterRecord,
    ModelComparison as ModelComparison,
    identify_inerter as identify_inerter,
)
from ._steady_state import SolverSettings as SolverSettings
from ._substructuring import (
    Substructuring as Substructuring,
    SubstructuringStability as SubstructuringStability,
    simulate_substructuring as simulate_substructuring,
    substructuring_stability as substructuring_stability,
)
from ._system import (
    PAPER_AMPLITUDES as PAPER_AMPLITUDES,
    PAPER_STROKE as PAPER_STROKE,
    TIDSystem as TIDSystem,
)

__version__ = "0.1.0"
