"""Rod detector (seed 001 §3.1): a black cylinder of known size lying on the table.

1. Segmentation: dark pixels (HSV value ≤ threshold). When the table itself is
   dark (a black mat), only dark pixels that stand above the table plane or
   have no depth are kept, so the rod is found on light and dark surfaces.
2. Connected regions that pass the elongation test (aspect ratio ≫ 1) and show
   depth evidence of standing above the table are rod candidates.
3. Silhouette pose (needs no depth on the rod): the two long image edges of the
   region back-project to planes tangent to the cylinder; the plane bisecting
   them contains the axis, and the axis lies one radius above the table, so the
   axis is where the bisector meets the table plane raised by r. The same edges
   give a diameter measurement.
4. Surface pose (when the rod has enough depth): the cylinder of known radius
   resting on the table is fitted to the visible surface points (robust least
   squares on the point-to-axis distance), not to their centroid — the visible
   half's centroid sits ~r·0.4 off the axis.
5. Ends: every pixel of the region is a ray; where it crosses the fitted
   (infinite) cylinder gives an axial interval. The rod's far end is the largest
   near-end of those intervals, its near end the smallest far-end: exact for a
   flat-capped cylinder, whatever the perspective. Centre = midpoint, length =
   distance between the ends.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import cv2
import numpy as np

from services.common.sensors import CameraIntrinsics
from services.common.settings import RodDetectionSettings
from services.vision.geometry import (
    CylinderAxis,
    Plane,
    pixel_rays,
    project,
    ray_cylinder_hits,
    ray_factors,
    resolution_scale,
    scaled_stride,
)
from services.vision.lsq import robust_least_squares
from services.vision.pose import estimate_pca_pose
from services.vision.results import RodDetection

Array = np.ndarray

_EDGE_FRACTION = 0.35  # use the middle ±35 % of the region's length for edge lines (away from the caps)
_MAX_FIT_POINTS = 800
_FOOTPRINT_CELL_M = 0.004  # table grid for the footprints of tall objects
# Pieces of one rod: elongated (aspect ≥ 2), at least a third of the rod's minimum area, axes within 8°,
# centres within half a rod width of each other's axis line.
_FRAGMENT_MIN_ASPECT = 2.0
_FRAGMENT_AREA_DIVISOR = 3
_FRAGMENT_MAX_ANGLE_DEG = 8.0
_FRAGMENT_MAX_OFFSET = 0.5


def dark_mask(color_rgb: Array, value_max: int) -> Array:
    """HSV value = max(R, G, B); dark where it is at most ``value_max``."""
    r, g, b = cv2.split(color_rgb)
    return cv2.max(cv2.max(r, g), b) <= value_max


def height_map(depth_m: Array, intr: CameraIntrinsics, plane: Plane) -> Array:
    """Height of every pixel's 3D point above the table plane (NaN where there is no depth)."""
    xs, ys = ray_factors(intr)
    n = plane.normal.astype(np.float32)
    scale = n[0] * xs[None, :] + n[1] * ys[:, None] + n[2]
    h = depth_m * scale + np.float32(plane.d)
    return np.where(depth_m > 0, h, np.float32(np.nan))


def heights_at(depth_m: Array, intr: CameraIntrinsics, plane: Plane, rows: Array, cols: Array) -> Array:
    """Heights above the table of the given pixels (NaN where there is no depth)."""
    z = depth_m[rows, cols].astype(float)
    h = (pixel_rays(intr, rows, cols) @ plane.normal) * z + plane.d
    return np.where(z > 0, h, np.nan)


def table_is_dark(
    color_rgb: Array, depth_m: Array, intr: CameraIntrinsics, plane: Plane, value_max: int, tol_m: float
) -> bool:
    """Is the table surface itself dark (a black mat)? Median value of on-table pixels, strided."""
    rows, cols = np.mgrid[4 : intr.height : 8, 4 : intr.width : 8]
    rows, cols = rows.ravel(), cols.ravel()
    with np.errstate(invalid="ignore"):
        on = np.abs(heights_at(depth_m, intr, plane, rows, cols)) < tol_m
    if not np.any(on):
        return False
    v = color_rgb[rows[on], cols[on]].max(axis=1)
    return bool(np.median(v) <= value_max)


def rod_width_px(intr: CameraIntrinsics, plane: Plane, diameter_m: float) -> float:
    """The rod's expected width in pixels where the optical axis meets the table (from depth and f)."""
    n_z = float(plane.normal[2])
    z = -plane.d / n_z if n_z < -1e-3 else 1.0
    return float(intr.fx * diameter_m / max(z, 0.05))


def _table_basis(plane: Plane) -> tuple[Array, Array]:
    n = plane.normal
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = a - (a @ n) * n
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _under_tall_objects(
    depth_m: Array, intr: CameraIntrinsics, plane: Plane, high: Array, cand: Array
) -> Array:
    """Candidate pixels (with depth) that stand on the table footprint of something taller than a rod.

    A black box beside the rod, or the side of a grey box, has its lower band at rod height; its
    upper part is taller than any rod, and on the table it stands on the same spot. So a pixel whose
    3-D point lies on the table footprint of tall points belongs to a taller object, not to a rod
    (this separates a neighbour touching the rod in the image by geometry, not by colour). Tested on
    every second pixel (the footprints are coarser than that) and returned at full resolution.
    """
    s = 2 * scaled_stride(1, intr)
    out = np.zeros(cand.shape, bool)
    hr, hc = np.nonzero(high[::s, ::s])
    cr, cc = np.nonzero(cand[::2, ::2])
    if len(hr) == 0 or len(cr) == 0:
        return out
    hr, hc, cr, cc = hr * s, hc * s, cr * 2, cc * 2
    e1, e2 = _table_basis(plane)
    cell = _FOOTPRINT_CELL_M

    def feet(r: Array, c: Array) -> tuple[Array, Array]:
        p = pixel_rays(intr, r, c) * depth_m[r, c][:, None].astype(float)
        return np.floor(p @ e1 / cell).astype(np.int64), np.floor(p @ e2 / cell).astype(np.int64)

    hu, hv = feet(hr, hc)
    cu, cv = feet(cr, cc)
    u0, v0 = min(hu.min(), cu.min()) - 2, min(hv.min(), cv.min()) - 2
    nu, nv = max(hu.max(), cu.max()) - u0 + 3, max(hv.max(), cv.max()) - v0 + 3
    if nu * nv > 4_000_000:  # a degenerate cloud (points far off): no footprint test
        return out
    counts = np.bincount((hu - u0) * nv + (hv - v0), minlength=nu * nv).reshape(nu, nv)
    # Two tall points in a cell: one noisy pixel on top of a rod is no tall object.
    tall = cv2.dilate((counts >= 2).astype(np.uint8), np.ones((3, 3), np.uint8))
    under = tall[cu - u0, cv - v0].astype(bool)
    half = np.zeros(((cand.shape[0] + 1) // 2, (cand.shape[1] + 1) // 2), np.uint8)
    half[cr[under] // 2, cc[under] // 2] = 1
    full = cv2.resize(half, (2 * half.shape[1], 2 * half.shape[0]), interpolation=cv2.INTER_NEAREST)
    return full[: cand.shape[0], : cand.shape[1]].astype(bool) & cand


def rod_candidate_mask(
    color_rgb: Array,
    depth_m: Array,
    intr: CameraIntrinsics,
    plane: Plane,
    params: RodDetectionSettings,
) -> Array:
    """Pixels that may show a rod: dark or specular (bright, grey) metal, from depth and colour together.

    - Dark pixels on a light table count whatever their depth; on a dark mat only where they stand
      above the table or have no depth (the mat is dark too).
    - Grey-bright pixels (a highlight on the tube) count where they stand at rod height above the table.
    - Nothing taller than a rod counts, nor anything on the footprint of a taller object.
    - Gaps left by a highlight without depth are bridged with a closing scaled to the rod's width in
      pixels at the table's distance, so it grows with the image and shrinks with range.
    """
    valid = depth_m > 0
    thr = max(params.above_table_min_m, 3.0 * plane.rms_m)
    h_top = params.diameter_m + max(0.005, 2.5 * plane.rms_m)
    r, g, b = cv2.split(color_rgb)
    v = cv2.max(cv2.max(r, g), b)
    chroma = cv2.subtract(v, cv2.min(cv2.min(r, g), b))
    dark = v <= params.dark_value_max
    xs, ys = ray_factors(intr)
    n = plane.normal.astype(np.float32)
    heights = n[0] * xs[None, :] + n[1] * ys[:, None]
    heights += n[2]
    heights *= depth_m
    heights += np.float32(plane.d)  # where there is no depth this is the camera's height: masked below
    high = heights >= h_top
    high &= valid
    band = heights > thr
    band &= valid
    band &= ~high
    # A highlight is grey-bright, at rod height or without depth (a saturated stripe often returns
    # none), and on black metal: within a rod's width of dark pixels.
    width_px = rod_width_px(intr, plane, params.diameter_m)
    specular = chroma <= params.specular_chroma_max
    specular &= band | ~valid
    specular &= ~dark
    near = max(3, round(width_px) | 1)
    specular &= cv2.dilate(dark.view(np.uint8), np.ones((near, near), np.uint8)).view(bool)
    tol = max(thr, 0.005)
    sub_h, sub_v = heights[4::8, 4::8], valid[4::8, 4::8]
    on_table = sub_v & (np.abs(sub_h) < tol)
    dark_table = bool(np.any(on_table)) and bool(np.median(v[4::8, 4::8][on_table]) <= params.dark_value_max)
    if dark_table:
        dark &= band | ~valid
    else:
        dark &= ~high
    cand = dark | specular
    cand &= ~_under_tall_objects(depth_m, intr, plane, high, cand & valid)
    mask: Array = cand.astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))  # isolated noisy pixels
    k = max(3, round(params.gap_close_fraction * width_px) | 1)
    return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))


def detect_rods(
    color_rgb: Array,
    depth_m: Array,
    intr: CameraIntrinsics,
    plane: Plane,
    params: RodDetectionSettings,
) -> tuple[list[RodDetection], list[str], dict[str, float]]:
    """All rods in the frame, best first; notes on rejected candidates; stage timings (ms)."""
    t0 = time.perf_counter()
    t_pose = 0.0
    notes: list[str] = []
    r = params.diameter_m / 2.0
    above_thr = max(params.above_table_min_m, 1.5 * plane.rms_m)
    h_max = params.diameter_m * 1.6 + 0.01
    mask = rod_candidate_mask(color_rgb, depth_m, intr, plane, params)
    # Labels without OpenCV's stats (which cost 20x the labelling here).
    n_lab, labels = cv2.connectedComponents(mask, connectivity=8)
    areas = np.bincount(labels.ravel(), minlength=n_lab)

    # Pixel lists of every labelled region in one pass (sorted by label), not one full-image scan each.
    flat = np.flatnonzero(labels)
    flat = flat[np.argsort(labels.ravel()[flat], kind="stable")]
    starts = np.concatenate([[0], np.cumsum(areas[1:])])

    rods: list[RodDetection] = []
    min_area = params.min_area_px * resolution_scale(intr) ** 2
    fragments: list[tuple[int, tuple[Array, Array, float, Array], int]] = []  # (label, shape, area)

    def pixels(ks: list[int]) -> tuple[Array, Array]:
        idx = np.concatenate([flat[starts[k - 1] : starts[k]] for k in ks])
        return np.divmod(idx, labels.shape[1])

    def try_region(ks: list[int], report: bool) -> tuple[RodDetection | None, bool]:
        """Fit a rod to the union of these labelled regions: (rod or None, may it be a fragment)."""
        nonlocal t_pose
        rows, cols = pixels(ks)
        y0, x0 = int(rows.min()), int(cols.min())
        h, w = int(rows.max()) - y0 + 1, int(cols.max()) - x0 + 1
        crop = (slice(max(y0 - 2, 0), y0 + h + 2), slice(max(x0 - 2, 0), x0 + w + 2))
        comp = np.isin(labels[crop], ks)
        oy, ox = crop[0].start, crop[1].start
        shape = _region_shape(rows, cols)
        where = f"px ({x0 + w // 2}, {y0 + h // 2})"
        if shape is None or shape[2] < params.min_aspect_ratio:
            if report and shape is not None and shape[2] >= 1.8:
                notes.append(
                    f"dark region at {where} not elongated enough "
                    f"(aspect {shape[2]:.1f} < {params.min_aspect_ratio})"
                )
            return None, shape is not None and shape[2] >= _FRAGMENT_MIN_ASPECT
        comp_h = heights_at(depth_m, intr, plane, rows, cols)
        comp_valid = np.isfinite(comp_h)
        if np.count_nonzero(comp_valid) >= 10:
            above_frac = float(np.mean((comp_h[comp_valid] > above_thr) & (comp_h[comp_valid] < h_max)))
            if above_frac < params.min_above_fraction:
                notes.append(
                    f"dark elongated region at {where} lies flat on the table ({above_frac:.0%} of it at "
                    f"rod height, {params.min_above_fraction:.0%} needed), not a rod"
                )
                return None, False
        tp = time.perf_counter()
        det, why = _fit_rod(comp, (oy, ox), rows, cols, shape, depth_m, intr, plane, params, r)
        t_pose += time.perf_counter() - tp
        if det is None and report:
            notes.append(why)
        return det, det is None and "length" in why

    for k in np.nonzero(areas >= min_area / _FRAGMENT_AREA_DIVISOR)[0]:
        if k == 0:
            continue
        whole = areas[k] >= min_area
        det, fragment = try_region([int(k)], report=whole)
        if det is not None:
            rods.append(det)
        elif fragment:
            rows, cols = pixels([int(k)])
            shape = _region_shape(rows, cols)
            if shape is not None:
                fragments.append((int(k), shape, int(areas[k])))
    rods += _merge_fragments(fragments, try_region, rod_width_px(intr, plane, params.diameter_m), notes)
    rods.sort(key=lambda d: d.confidence, reverse=True)
    if len(rods) > params.max_rods:
        notes.append(f"{len(rods)} rods found, reporting the best {params.max_rods}")
        rods = rods[: params.max_rods]
    total = (time.perf_counter() - t0) * 1e3
    return rods, notes, {"rod_segmentation": total - t_pose * 1e3, "rod_pose": t_pose * 1e3}


def _merge_fragments(
    fragments: list[tuple[int, tuple[Array, Array, float, Array], int]],
    try_region: Callable[[list[int], bool], tuple[RodDetection | None, bool]],
    width_px: float,
    notes: list[str],
) -> list[RodDetection]:
    """Pieces of one rod (cut by a highlight or an occluder across it) that lie on one line and fit
    one cylinder together: largest pairs first, each piece used once."""
    found: list[RodDetection] = []
    used: set[int] = set()
    order = sorted(range(len(fragments)), key=lambda i: -fragments[i][2])
    for ia, i in enumerate(order):
        for j in order[ia + 1 :]:
            (ka, sa, _), (kb, sb, _) = fragments[i], fragments[j]
            if ka in used or kb in used:
                continue
            if abs(float(sa[0] @ sb[0])) < np.cos(np.radians(_FRAGMENT_MAX_ANGLE_DEG)):
                continue
            d = sb[3] - sa[3]
            off = max(abs(float(d @ sa[1])), abs(float(d @ sb[1])))  # across either piece's axis
            if off > _FRAGMENT_MAX_OFFSET * width_px:
                continue
            det, _ = try_region([ka, kb], False)
            if det is not None:
                used |= {ka, kb}
                found.append(det)
                notes.append(f"rod found from two collinear pieces ({ka}, {kb}) fitted as one cylinder")
    return found


def _region_shape(rows: Array, cols: Array) -> tuple[Array, Array, float, Array] | None:
    """Image major/minor directions (unit, (x, y)), aspect ratio and centre of a pixel region.

    The aspect ratio is sqrt of the ratio of the principal variances: length/width for a bar.
    """
    if len(rows) < 10:
        return None
    pts = np.column_stack([cols, rows]).astype(float)
    c = pts.mean(axis=0)
    q = pts - c
    evals, evecs = np.linalg.eigh(q.T @ q / len(pts))
    e, f = evecs[:, 1], evecs[:, 0]
    aspect = float(np.sqrt(evals[1] / max(evals[0], 1e-6)))
    return e, f, aspect, c


def _edge_planes(
    comp: Array, offset: tuple[int, int], shape: tuple[Array, Array, float, Array], intr: CameraIntrinsics
) -> tuple[Array, Array] | None:
    """Unit normals of the two planes through the camera tangent to the rod (positive inside)."""
    contours, _ = cv2.findContours(comp.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    # every outer contour: a rod merged from two pieces has one per piece
    contour = np.concatenate([c.reshape(-1, 2) for c in contours]).astype(float) + [offset[1], offset[0]]
    e, f, _, c = shape
    a = (contour - c) @ e
    b = (contour - c) @ f
    span = a.max() - a.min()
    mid = 0.5 * (a.max() + a.min())
    central = np.abs(a - mid) < _EDGE_FRACTION * span
    normals = []
    for side in (1.0, -1.0):
        pts = contour[central & (side * b > 0)]
        if len(pts) < 8:
            return None
        vx, vy, x0, y0 = cv2.fitLine(pts.astype(np.float32), cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
        n2d = np.array([-vy, vx], dtype=float)
        if n2d @ (side * f) < 0:
            n2d = -n2d  # outward
        # Contour pixels are the outermost pixel centres: the true edge lies half a pixel further out.
        line = np.array([n2d[0], n2d[1], -(n2d[0] * x0 + n2d[1] * y0) - 0.5])
        n3 = -(intr.K.T @ line)  # plane through the camera; interior rays give n3·ray > 0
        normals.append(n3 / np.linalg.norm(n3))
    return normals[0], normals[1]


def _silhouette_axis(n1: Array, n2: Array, plane: Plane, r: float) -> CylinderAxis | None:
    """Axis = bisector of the tangent planes ∩ table plane raised by r."""
    m = n1 - n2
    direction = np.cross(m, plane.normal)
    norm = np.linalg.norm(direction)
    if norm < 1e-9:
        return None
    A = np.vstack([m, plane.normal])
    b = np.array([0.0, r - plane.d])
    point = np.linalg.lstsq(A, b, rcond=None)[0]
    return CylinderAxis(point, direction / norm)


def _measured_radius(n1: Array, n2: Array, plane: Plane, near: Array) -> float:
    """Radius from the silhouette alone: the axis is as far from both tangent planes as from the table."""
    A = np.vstack([n1 - n2, n1 - plane.normal])
    b = np.array([0.0, plane.d])
    p0 = np.linalg.lstsq(A, b, rcond=None)[0]
    u = np.cross(A[0], A[1])
    if np.linalg.norm(u) < 1e-9:
        return float("nan")
    u /= np.linalg.norm(u)
    p = p0 + ((near - p0) @ u) * u
    return float(0.5 * (n1 @ p + n2 @ p))


def _surface_fit(
    points: Array, init: CylinderAxis, plane: Plane, r: float, loss_scale: float
) -> tuple[CylinderAxis, Array]:
    """Cylinder of radius r resting on the table, fitted to the measured depths: (axis, residuals).

    The residual is measured depth minus the depth where the pixel's ray meets the model surface —
    the direction the sensor noise acts in. (Point-to-axis distances are biased when the noise is
    a fifth of the radius, which tilts the axis by up to ~1°.)
    """
    n = plane.normal
    u0 = init.direction - (init.direction @ n) * n
    u0 /= np.linalg.norm(u0)
    e2 = np.cross(n, u0)
    base = init.point - (plane.signed_distance(init.point[None])[0] - r) * n  # on the raised plane
    z = points[:, 2]
    rays = points / z[:, None]

    def axis(x: Array) -> CylinderAxis:
        th, s = x
        return CylinderAxis(base + s * e2, np.cos(th) * u0 + np.sin(th) * e2)

    def residuals(x: Array) -> Array:
        s_in, _, miss = ray_cylinder_hits(rays, axis(x), r)
        return z - s_in + miss

    fit = robust_least_squares(
        residuals, np.zeros(2), step=np.array([1e-5, 1e-6]), loss_scale=loss_scale, tol=np.array([1e-5, 1e-6])
    )
    return axis(fit.x), fit.residuals


def _chord_ends(rays: Array, axis: CylinderAxis, r: float) -> tuple[float, float]:
    """Axial extent of the rod from its silhouette rays (see module docstring, step 5)."""
    u, a0 = axis.direction, axis.point
    s_in, s_out, _ = ray_cylinder_hits(
        rays, axis, r
    )  # rays that just miss (quantisation) use the closest approach
    du = rays @ u
    t1 = s_in * du - a0 @ u
    t2 = s_out * du - a0 @ u
    near_end = np.minimum(t1, t2)
    far_end = np.maximum(t1, t2)
    k = max(1, len(rays) // 500)  # ignore the few most extreme pixels (mask noise)
    hi = float(np.partition(near_end, len(near_end) - k)[len(near_end) - k])
    lo = float(np.partition(far_end, k - 1)[k - 1])
    return lo, hi


def _fit_rod(
    comp: Array,
    offset: tuple[int, int],
    rows: Array,
    cols: Array,
    shape: tuple[Array, Array, float, Array],
    depth_m: Array,
    intr: CameraIntrinsics,
    plane: Plane,
    params: RodDetectionSettings,
    r: float,
) -> tuple[RodDetection | None, str]:
    where = f"px ({shape[3][0]:.0f}, {shape[3][1]:.0f})"
    planes = _edge_planes(comp, offset, shape, intr)
    sil = _silhouette_axis(*planes, plane, r) if planes is not None else None

    # Depth on the rod, away from its outline (edge pixels carry flying depth).
    inner = cv2.erode(comp.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    ir, ic = np.nonzero(inner)
    ir, ic = ir + offset[0], ic + offset[1]
    z = depth_m[ir, ic]
    hh = heights_at(depth_m, intr, plane, ir, ic)
    with np.errstate(invalid="ignore"):
        ok = (z > 0) & (hh > 0.1 * r) & (hh < 2.6 * r)
    pts = pixel_rays(intr, ir[ok], ic[ok]) * z[ok, None].astype(float)
    n_depth = len(pts)
    if n_depth > _MAX_FIT_POINTS:  # an even spread is plenty for two parameters
        pts = pts[np.linspace(0, n_depth - 1, _MAX_FIT_POINTS).astype(int)]

    init = sil
    if init is None and n_depth >= params.min_depth_points:
        init = _pca_axis(pts, plane, r)
    if init is None:
        return None, f"dark elongated region at {where}: no usable outline or depth for a pose"
    method, residuals = "silhouette", None
    axis = init
    if n_depth >= params.min_depth_points:
        axis, residuals = _surface_fit(pts, init, plane, r, params.fit_loss_scale_m)
        method = "surface_fit"
    u = axis.direction
    if u[0] < 0 or (abs(u[0]) < 1e-6 and u[1] < 0):
        u = -u
    axis = CylinderAxis(axis.point, u)
    rays = pixel_rays(intr, rows, cols)
    lo, hi = _chord_ends(rays, axis, r)
    center = axis.point + 0.5 * (lo + hi) * u
    length = hi - lo
    if planes is not None:
        diameter = 2.0 * _measured_radius(*planes, plane, center)
    else:  # silhouette edges unusable: the widest ray-to-axis distance
        diameter = 2.0 * float(np.percentile(_ray_axis_distance(rays, axis), 98))
    if not np.isfinite(diameter):
        diameter = params.diameter_m

    L0, D0 = params.length_m, params.diameter_m
    if abs(length / L0 - 1.0) > params.length_tolerance:
        return None, (
            f"dark elongated region at {where}: length {length * 1000:.0f} mm is not the "
            f"rod's {L0 * 1000:.0f} mm ± {params.length_tolerance:.0%}"
        )
    if abs(diameter / D0 - 1.0) > params.diameter_tolerance:
        return None, (
            f"dark elongated region at {where}: diameter {diameter * 1000:.1f} mm is not the "
            f"rod's {D0 * 1000:.1f} mm ± {params.diameter_tolerance:.0%}"
        )
    taller = _taller_than_model(depth_m, intr, plane, axis, lo, hi, r)
    if taller > params.max_taller_fraction:
        return None, (
            f"dark elongated region at {where} stands higher than the rod's {D0 * 1000:.1f} mm diameter "
            f"({taller:.0%} of the depth there nearer than a rod's surface): a larger object, not the rod"
        )
    score = np.exp(-0.5 * ((length - L0) / (0.1 * L0)) ** 2) * np.exp(
        -0.5 * ((diameter - D0) / (0.25 * D0)) ** 2
    )
    if residuals is not None:
        score *= float(np.mean(np.abs(residuals) < 2.5 * params.fit_loss_scale_m))
        if sil is not None:  # disagreement between outline and surface lowers trust
            score *= float(np.exp(-0.5 * (_line_gap(sil, axis, center) / (2 * params.fit_loss_scale_m)) ** 2))
    else:
        score *= 0.6  # outline only
    ends = np.array([axis.point + lo * u, axis.point + hi * u])
    det = RodDetection(
        center_cam=center,
        axis_cam=u,
        up_cam=plane.normal.copy(),
        length_m=float(length),
        diameter_m=float(diameter),
        confidence=float(np.clip(score, 0.0, 1.0)),
        method=method,
        n_depth_points=n_depth,
        n_pixels=len(rows),
        endpoints_px=project(ends, intr),
    )
    return det, ""


def _taller_than_model(
    depth_m: Array, intr: CameraIntrinsics, plane: Plane, axis: CylinderAxis, lo: float, hi: float, r: float
) -> float:
    """Share of the depth pixels inside the fitted rod's image (its middle 60 % across) that lie
    nearer than the rod's surface: high for a thicker bar trimmed to rod height by the mask."""
    ends = np.array([axis.point + lo * axis.direction, axis.point + hi * axis.direction])
    uv = project(ends, intr)
    z_mid = float(0.5 * (ends[0, 2] + ends[1, 2]))
    thick = max(1, int(0.6 * intr.fx * 2 * r / max(z_mid, 0.05)))
    x0, y0 = np.floor(uv.min(axis=0)).astype(int) - thick
    x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + thick
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, intr.width), min(y1, intr.height)
    if x1 <= x0 or y1 <= y0:
        return 0.0
    band = np.zeros((y1 - y0, x1 - x0), np.uint8)
    a, b = np.rint(uv - [x0, y0]).astype(int)
    cv2.line(band, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), 1, thickness=thick)
    rows, cols = np.nonzero(band[::2, ::2])
    rows, cols = rows * 2 + y0, cols * 2 + x0
    z = depth_m[rows, cols].astype(float)
    ok = z > 0
    if np.count_nonzero(ok) < 20:
        return 0.0
    s_in, _, _ = ray_cylinder_hits(pixel_rays(intr, rows[ok], cols[ok]), axis, r)
    tol = max(0.008, 2.5 * plane.rms_m)
    return float(np.mean(z[ok] < s_in - tol))


def _pca_axis(pts: Array, plane: Plane, r: float) -> CylinderAxis:
    """Initial axis from the depth points alone: the principal axis of their table footprint."""
    pose = estimate_pca_pose(plane.project(pts))
    return CylinderAxis(pose.position + r * plane.normal, pose.rotation[:, 0])


def _ray_axis_distance(rays: Array, axis: CylinderAxis) -> Array:
    u, a0 = axis.direction, axis.point
    cr = np.cross(rays, u)
    norm = np.linalg.norm(cr, axis=1)
    return np.abs(cr @ (-a0)) / np.maximum(norm, 1e-12)


def _line_gap(a: CylinderAxis, b: CylinderAxis, at: Array) -> float:
    """Distance between two axis lines near ``at``."""
    pa = a.point + ((at - a.point) @ a.direction) * a.direction
    pb = b.point + ((at - b.point) @ b.direction) * b.direction
    return float(np.linalg.norm(pa - pb))
