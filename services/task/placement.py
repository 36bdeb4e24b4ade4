"""Where to stand the rod: the configured spot, or the nearest free one around it (pure)."""

from __future__ import annotations

import math

import numpy as np

from services.task.ports import Observation, SeenBox


def _box_distance_xy(p: np.ndarray, box: SeenBox) -> float:
    d = np.maximum(np.maximum(box.min[:2] - p, 0.0), p - box.max[:2])
    return float(np.linalg.norm(d))


def place_candidates(
    preferred_xy: np.ndarray,
    region_min: np.ndarray,
    region_max: np.ndarray,
    step_m: float = 0.04,
    rings: int = 4,
) -> list[np.ndarray]:
    """The preferred spot, then rings of 8·k spots around it, nearest first, inside the region."""
    out = [np.asarray(preferred_xy, dtype=float)]
    for k in range(1, rings + 1):
        n = 8 * k
        for i in range(n):
            a = 2 * math.pi * i / n
            out.append(out[0] + k * step_m * np.array([math.cos(a), math.sin(a)]))
    return [p for p in out if np.all(p >= region_min) and np.all(p <= region_max)]


def free_place_xy(
    obs: Observation, candidates: list[np.ndarray], clearance_m: float, skip_rod: int | None = 0
) -> np.ndarray | None:
    """The first candidate at least ``clearance_m`` (plus the objects' own size) from every other
    object on the table; the rod being moved (index ``skip_rod``) does not count."""
    for p in candidates:
        ok = all(np.linalg.norm(c.centroid[:2] - p) >= c.size / math.sqrt(2) + clearance_m for c in obs.cubes)
        ok = ok and all(_box_distance_xy(p, b) >= clearance_m for b in obs.obstacles)
        for i, r in enumerate(obs.rods):
            if i == skip_rod or not ok:
                continue
            a = r.axis[:2] / max(float(np.linalg.norm(r.axis[:2])), 1e-9)
            t = float(np.clip(np.dot(p - r.center[:2], a), -r.length / 2, r.length / 2))
            ok = bool(np.linalg.norm(r.center[:2] + t * a - p) >= r.diameter / 2 + clearance_m)
        if ok:
            return p
    return None
