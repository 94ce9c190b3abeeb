"""Smooth maxima of terms (log peaks) with their exact curvature: the log-sum-exp of the
candidates, its gradient and its derivatives along the design variables."""

from typing import NamedTuple

import numpy as np


class Terms(NamedTuple):
    """A smooth maximum's terms (log peaks), whether each is a candidate, their gradients
    (u0, u1, parameters `Context.other`) and those gradients' derivatives along u0 and u1."""

    values: np.ndarray
    mask: np.ndarray
    grad: np.ndarray
    dgrad: np.ndarray


def term_weights(candidates: Terms, sharpness):
    """The smooth maximum G = ln(sum exp(s T)) / s of the candidate terms T and each
    term's weight in it, exp(s (T - G)) (0 for a term that is no candidate; they sum to
    1): `(inf, None)` where no candidate is finite."""
    terms = np.where(candidates.mask, candidates.values, -np.inf)
    top = np.max(terms)
    if not np.isfinite(top):
        return np.inf, None
    weights = np.exp(sharpness * (terms - top))
    total = weights.sum()
    return top + np.log(total) / sharpness, weights / total


def smooth_max(candidates: Terms, sharpness):
    """Smooth maximum G = ln(sum exp(s T)) / s of the candidate terms T, its gradient in
    all coordinates and its derivatives along u0, u1 (rows) in all coordinates: the exact
    curvature of the log-sum-exp plus the weighted curvatures of the terms."""
    _, mask, grad, dgrad = candidates
    value, weights = term_weights(candidates, sharpness)
    if weights is None:
        return value, None, None
    grad = np.where(mask[:, None], grad, 0.0)
    dgrad = np.where(mask[:, None, None], dgrad, 0.0)
    g = weights @ grad
    hess = sharpness * (np.einsum("n,ni,nj->ij", weights, grad[:, :2], grad) - np.outer(g[:2], g))
    hess += np.einsum("n,nij->ij", weights, dgrad)
    return value, g, hess
