"""How well the rod's confidence says what it means: P(the reported pose is accurate).

"Accurate" is the hard set's target: centre within 2 mm and axis within 1° of the truth. ``make bench``
scores the detector's confidence against it on the hard scene set (expected calibration error, Brier
score); on 263 hard-set rods at 640×480 the score needed no remapping: ECE 0.005 — an isotonic
(scikit-learn) recalibration fitted on the same set scored worse (0.007), so none is applied.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

Array = np.ndarray


def expected_calibration_error(confidence: ArrayLike, accurate: ArrayLike, bins: int = 10) -> float:
    """Mean |confidence − observed accuracy| over equal-width bins, weighted by their counts."""
    c = np.asarray(confidence, dtype=float)
    y = np.asarray(accurate, dtype=float)
    idx = np.minimum((c * bins).astype(int), bins - 1)
    err = 0.0
    for b in range(bins):
        m = idx == b
        if m.any():
            err += m.sum() / len(c) * abs(c[m].mean() - y[m].mean())
    return float(err)


def brier_score(confidence: ArrayLike, accurate: ArrayLike) -> float:
    c = np.asarray(confidence, dtype=float)
    return float(np.mean((c - np.asarray(accurate, dtype=float)) ** 2))


def is_accurate(
    center_error_m: Array, axis_error_deg: Array, center_tol_m: float, axis_tol_deg: float
) -> Array:
    return (np.asarray(center_error_m) <= center_tol_m) & (np.asarray(axis_error_deg) <= axis_tol_deg)
