"""Antipodal grasp candidates per shape, in the object frame, before scoring (step 1 of
:func:`services.grasp.synthesis.compute_grasps`): pads on opposite faces (box), across the diameter
or on the flat ends (cylinder), through the centre (sphere); several approach directions, jaw
orientations (the two 180°-symmetric wrist options) and offsets along the free axis. Sampling around
a cylinder's axis is anchored to gravity, so a lying cylinder always gets the exact top-down grasp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.common.frames import tool_rotation
from services.common.settings import GraspSettings
from services.grasp.geometry import pose

Array = np.ndarray

N_AROUND = 8  # samples around a cylinder's axis / closing directions per sphere approach
N_ALONG = 5  # offsets along a free axis


@dataclass(frozen=True)
class Candidate:
    """A grasp in the object frame, before scoring."""

    T_object_tool: Array
    width: float
    points: Array  # contacts (k, 3), object frame
    normals: Array  # inward (k, 3)
    centering: float
    label: str


def _contact_line(a: Array, b: Array, n: int) -> Array:
    if np.linalg.norm(b - a) < 1e-6:
        return a[None]
    return a[None] + np.linspace(0.0, 1.0, n)[:, None] * (b - a)[None]


def _samples(half_range: float, n: int) -> Array:
    return np.linspace(-half_range, half_range, n) if half_range > 1e-3 else np.zeros(1)


def _pair(line_pos: Array, line_neg: Array, n_pos: Array, n_neg: Array) -> tuple[Array, Array]:
    points = np.vstack([line_pos, line_neg])
    normals = np.vstack([np.repeat(n_pos[None], len(line_pos), 0), np.repeat(n_neg[None], len(line_neg), 0)])
    return points, normals


def box_candidates(size: tuple[float, float, float], cfg: GraspSettings, stroke_m: float) -> list[Candidate]:
    g, npl = cfg.gripper, cfg.force_closure.points_per_line
    s = np.asarray(size, dtype=float)
    eye = np.eye(3)
    out: list[Candidate] = []
    for i in range(3):
        width = s[i]
        if width + g.width_margin_m > stroke_m or width < g.min_width_m:
            continue
        for j in range(3):
            if j == i:
                continue
            k = 3 - i - j
            depth = min(s[j] / 2, cfg.max_grasp_depth_m)
            for sigma in (1.0, -1.0):
                tcp_j = sigma * (s[j] / 2 - depth)
                lo_j, hi_j = (
                    max(tcp_j - g.pad_height_m / 2, -s[j] / 2),
                    min(tcp_j + g.pad_height_m / 2, s[j] / 2),
                )
                for o in _samples(max(0.0, s[k] / 2 - g.pad_length_m / 2), N_ALONG):
                    lo_k, hi_k = max(o - g.pad_length_m / 2, -s[k] / 2), min(o + g.pad_length_m / 2, s[k] / 2)
                    if hi_j <= lo_j or hi_k <= lo_k:
                        continue
                    # the contact patch as a line along its longer side, through its middle
                    a, b = np.zeros(3), np.zeros(3)
                    if hi_k - lo_k >= hi_j - lo_j:
                        a[k], b[k] = lo_k, hi_k
                        a[j] = b[j] = (lo_j + hi_j) / 2
                    else:
                        a[j], b[j] = lo_j, hi_j
                        a[k] = b[k] = (lo_k + hi_k) / 2
                    line = _contact_line(a, b, npl)
                    lp, ln = line.copy(), line.copy()
                    lp[:, i], ln[:, i] = s[i] / 2, -s[i] / 2
                    pts, nrm = _pair(lp, ln, -eye[i], eye[i])
                    centering = float(
                        np.clip(1 - 0.5 * abs(o) / (s[k] / 2) - 0.5 * abs(tcp_j) / (s[j] / 2), 0, 1)
                    )
                    p = np.zeros(3)
                    p[j], p[k] = tcp_j, o
                    for tau in (1.0, -1.0):
                        R = tool_rotation(-sigma * eye[j], tau * eye[i])
                        label = (
                            f"box: close {'xyz'[i]}, from {'+' if sigma > 0 else '-'}{'xyz'[j]}, offset {o:+.3f} m, "
                            f"jaw {'+' if tau > 0 else '-'}"
                        )
                        out.append(Candidate(pose(R, p), float(width), pts, nrm, centering, label))
    return out


def _phi0(down_obj: Array) -> float:
    """Angle about the object z axis whose side approach points most nearly down (gravity anchor)."""
    d = down_obj[:2]
    n = float(np.linalg.norm(d))
    return math.atan2(d[0] / n, -d[1] / n) if n > 1e-6 else 0.0


def cylinder_candidates(
    radius: float, length: float, cfg: GraspSettings, stroke_m: float, down_obj: Array
) -> list[Candidate]:
    g, npl = cfg.gripper, cfg.force_closure.points_per_line
    h2 = length / 2
    ez = np.array([0.0, 0.0, 1.0])
    out: list[Candidate] = []
    width = 2 * radius
    if width + g.width_margin_m <= stroke_m and width >= g.min_width_m:
        phi0 = _phi0(down_obj)
        for m in range(N_AROUND):
            phi = phi0 + m * math.pi / N_AROUND
            u = np.array([math.cos(phi), math.sin(phi), 0.0])
            v = np.array([-math.sin(phi), math.cos(phi), 0.0])
            # side approach, perpendicular to the axis: the pads lie along the axis
            shift = max(0.0, radius - cfg.max_grasp_depth_m)
            if shift <= g.pad_height_m / 2:
                for t in _samples(max(0.0, h2 - g.pad_length_m / 2), N_ALONG):
                    lo, hi = max(t - g.pad_length_m / 2, -h2), min(t + g.pad_length_m / 2, h2)
                    line = _contact_line(lo * ez, hi * ez, npl)
                    pts, nrm = _pair(line + radius * u, line - radius * u, -u, u)
                    for sigma in (1.0, -1.0):
                        p = t * ez + sigma * shift * v
                        for tau in (1.0, -1.0):
                            R = tool_rotation(-sigma * v, tau * u)
                            label = (
                                f"cylinder: side, {math.degrees(phi - phi0):.0f}° from top, offset {t:+.3f} m, "
                                f"jaw {'+' if tau > 0 else '-'}"
                            )
                            out.append(Candidate(pose(R, p), width, pts, nrm, float(1 - abs(t) / h2), label))
            # end approach, along the axis: the pads touch lines parallel to the axis
            depth = min(h2, cfg.max_grasp_depth_m)
            for sigma in (1.0, -1.0):
                tz = sigma * (h2 - depth)
                lo, hi = max(tz - g.pad_height_m / 2, -h2), min(tz + g.pad_height_m / 2, h2)
                line = _contact_line(lo * ez, hi * ez, npl)
                pts, nrm = _pair(line + radius * u, line - radius * u, -u, u)
                for tau in (1.0, -1.0):
                    R = tool_rotation(-sigma * ez, tau * u)
                    label = f"cylinder: from the {'+' if sigma > 0 else '-'}z end, around {math.degrees(phi):.0f}°"
                    out.append(Candidate(pose(R, tz * ez), width, pts, nrm, float(1 - abs(tz) / h2), label))
    # grip on the flat ends (closing along the axis) when the cylinder is short enough
    if length + g.width_margin_m <= stroke_m and length >= g.min_width_m:
        depth = min(radius, cfg.max_grasp_depth_m)
        for m in range(N_AROUND):
            beta = m * 2 * math.pi / N_AROUND
            w = np.array([math.cos(beta), math.sin(beta), 0.0])
            w_perp = np.array([-math.sin(beta), math.cos(beta), 0.0])
            tw = radius - depth
            half_chord = math.sqrt(max(radius**2 - tw**2, 0.0))
            x = min(g.pad_length_m / 2, half_chord)
            line = _contact_line(tw * w - x * w_perp, tw * w + x * w_perp, npl)
            pts, nrm = _pair(line + h2 * ez, line - h2 * ez, -ez, ez)
            for tau in (1.0, -1.0):
                R = tool_rotation(-w, tau * ez)
                label = f"cylinder: ends, from {math.degrees(beta):.0f}°"
                out.append(Candidate(pose(R, tw * w), length, pts, nrm, float(1 - tw / radius), label))
    return out


def _fibonacci_directions(n: int) -> Array:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    r = np.sqrt(1 - z * z)
    phi = k * math.pi * (3 - math.sqrt(5))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def sphere_candidates(radius: float, cfg: GraspSettings, stroke_m: float, down_obj: Array) -> list[Candidate]:
    g = cfg.gripper
    width = 2 * radius
    if width + g.width_margin_m > stroke_m or width < g.min_width_m:
        return []
    shift = radius - min(radius, cfg.max_grasp_depth_m)
    if shift > g.pad_height_m / 2:
        return []
    out: list[Candidate] = []
    approaches = np.vstack([down_obj[None], _fibonacci_directions(16)])
    for a in approaches:
        helper = np.eye(3)[int(np.argmin(np.abs(a)))]
        u0 = np.cross(a, helper)
        u0 /= np.linalg.norm(u0)
        u1 = np.cross(a, u0)
        for m in range(N_AROUND // 2):
            ang = m * math.pi / (N_AROUND // 2)
            u = math.cos(ang) * u0 + math.sin(ang) * u1
            pts, nrm = _pair((radius * u)[None], (-radius * u)[None], -u, u)
            for tau in (1.0, -1.0):
                R = tool_rotation(a, tau * u)
                out.append(Candidate(pose(R, -shift * a), width, pts, nrm, 1.0, "sphere: through the centre"))
    return out
