"""The pace of a guarded approach along its straight tool line (pure).

A touch-down is slow only where contact can come: the tool goes at the approach speed to a band
above the expected contact and at the touch-down speed through the band and the overtravel, so the
force guard still stops it gently. The joint path stays the planned one; only its timing changes.
"""

from __future__ import annotations

import math

import numpy as np

from services.kinematics.trajectory import Array, JointTrajectory

TOOL_ACCELERATION_M_S2 = 1.0  # speed changes along the line (gentle on a carried object)


def tool_speed_profile(
    distance: Array, approach_m_s: float, touch_m_s: float, band_from_m: float, accel: float
) -> Array:
    """Tool speed at each distance along the line: at most ``approach_m_s`` before ``band_from_m``
    and ``touch_m_s`` from there on, changed at ``accel``, from rest to rest."""
    cap = np.where(distance < band_from_m, max(approach_m_s, touch_m_s), touch_m_s)
    v = cap.astype(float).copy()
    v[0] = v[-1] = 0.0
    dd = np.diff(distance)
    for k in range(1, len(v)):  # speeding up no faster than accel
        v[k] = min(v[k], math.sqrt(v[k - 1] ** 2 + 2 * accel * dd[k - 1]))
    for k in range(len(v) - 2, -1, -1):  # and slowing down before the band and the end
        v[k] = min(v[k], math.sqrt(v[k + 1] ** 2 + 2 * accel * dd[k]))
    return v


def paced_on_line(
    traj: JointTrajectory,
    distance: Array,
    approach_m_s: float,
    touch_m_s: float,
    band_from_m: float,
    accel: float = TOOL_ACCELERATION_M_S2,
) -> JointTrajectory:
    """``traj`` (a straight tool line; ``distance`` the tool's distance from the start at each knot)
    retimed to the two-stage pace, the approach no faster than the planned peak tool speed."""
    d = np.maximum.accumulate(np.asarray(distance, dtype=float))
    keep = np.concatenate([[True], np.diff(d) > 1e-7])
    keep[-1] = True
    d, q = d[keep], traj.positions[keep]
    if len(d) < 3 or d[-1] <= 0:
        return traj
    # the planned tool speed bounds the new one: the joint limits hold wherever it is not exceeded
    planned = np.gradient(d, traj.times[keep])
    v = tool_speed_profile(d, min(approach_m_s, float(np.max(planned))), touch_m_s, band_from_m, accel)
    dt = 2 * np.diff(d) / np.maximum(v[:-1] + v[1:], 1e-9)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    dq_dd = np.gradient(q, d, axis=0)
    qd = dq_dd * v[:, None]
    qdd = np.gradient(qd, t, axis=0)
    qd[0] = qd[-1] = 0.0
    qdd[0] = qdd[-1] = 0.0
    return JointTrajectory(traj.joint_names, t, q, qd, qdd, dict(traj.meta))
