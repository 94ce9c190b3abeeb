"""Design of tuned inerter dampers (TIDs) whose inerter has dry friction."""

from ._band import (
    Peaks as Peaks,
)
from ._band import (
    default_omegas as default_omegas,
)
from ._band import (
    peak_response as peak_response,
)
from ._band import (
    peaks as peaks,
)
from ._cache import (
    default_cache_dir as default_cache_dir,
)
from ._cache import (
    enable_compilation_cache as enable_compilation_cache,
)
from ._design import (
    BestTunings as BestTunings,
)
from ._design import (
    best_tunings as best_tunings,
)
from ._device import (
    ForceSettings as ForceSettings,
)
from ._device import (
    InerterDevice as InerterDevice,
)
from ._identify import (
    IdentifySettings as IdentifySettings,
)
from ._identify import (
    InerterFit as InerterFit,
)
from ._identify import (
    InerterRecord as InerterRecord,
)
from ._identify import (
    ModelComparison as ModelComparison,
)
from ._identify import (
    identify_inerter as identify_inerter,
)
from ._linear import (
    Breakaway as Breakaway,
)
from ._linear import (
    LinearReceptance as LinearReceptance,
)
from ._linear import (
    breakaway_amplitude as breakaway_amplitude,
)
from ._linear import (
    den_hartog as den_hartog,
)
from ._linear import (
    den_hartog_tuning as den_hartog_tuning,
)
from ._linear import (
    linear_receptance as linear_receptance,
)
from ._linear import (
    paper_system as paper_system,
)
from ._linear import (
    stuck_receptance as stuck_receptance,
)
from ._response import (
    FrequencyResponse as FrequencyResponse,
)
from ._response import (
    frequency_response as frequency_response,
)
from ._retune import (
    RetuneResult as RetuneResult,
)
from ._retune import (
    RetuneSettings as RetuneSettings,
)
from ._retune import (
    retune as retune,
)
from ._robust import (
    RobustDesign as RobustDesign,
)
from ._robust import (
    RobustSettings as RobustSettings,
)
from ._robust import (
    TuningPerformance as TuningPerformance,
)
from ._robust import (
    robust_tune as robust_tune,
)
from ._robust import (
    tuning_performance as tuning_performance,
)
from ._sensitivity import (
    OptimumSensitivities as OptimumSensitivities,
)
from ._sensitivity import (
    Sensitivities as Sensitivities,
)
from ._sensitivity import (
    amplitude_sensitivities as amplitude_sensitivities,
)
from ._sensitivity import (
    sensitivities as sensitivities,
)
from ._settings import SolverSettings as SolverSettings
from ._substructuring import (
    Substructuring as Substructuring,
)
from ._substructuring import (
    SubstructuringStability as SubstructuringStability,
)
from ._substructuring import (
    simulate_substructuring as simulate_substructuring,
)
from ._substructuring import (
    substructuring_stability as substructuring_stability,
)
from ._system import (
    DEFAULT_FRICTION_WIDTH as DEFAULT_FRICTION_WIDTH,
)
from ._system import (
    PAPER_AMPLITUDES as PAPER_AMPLITUDES,
)
from ._system import (
    PAPER_STROKE as PAPER_STROKE,
)
from ._system import (
    TIDSystem as TIDSystem,
)

__version__ = "0.1.0"
