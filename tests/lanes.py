"""The peaks of many systems at once, for the tests' finite differences."""

import jax
import numpy as np

import tid_jax as tj
from tid_jax._peaks import response_peaks
from tid_jax._response import lane_response


def peaks_of(cases, band) -> np.ndarray:
    """The peaks (host, stroke) for each `(system, amplitude)` of `cases`, found as
    `tj.peaks` finds those of several amplitudes of one system: one batch, a lane for
    each case (a fraction of the time of a call for each). `[cases, 2]`, m."""
    systems = jax.tree.map(lambda *fields: np.array(fields, float), *(s for s, _ in cases))
    amplitudes = np.array([amplitude for _, amplitude in cases], float)
    settings = tj.SolverSettings()
    found = response_peaks(systems, lane_response(systems, amplitudes, band, settings),
                           settings)
    return np.stack([np.asarray(found.x_peak), np.asarray(found.y_peak)], axis=-1)
