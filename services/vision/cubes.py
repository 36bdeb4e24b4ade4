"""Cube and obstacle perception (seed 004): depth thresholds, table plane, DBSCAN, colour labels.

1. Cloud: depth within [min, max] on a pixel stride, points more than
   ``plane_residual_m`` (0.02 m) above the table plane.
2. DBSCAN (scikit-learn, ε = 0.015 m, minPts = 40 counted on a full 640-px-wide
   image; the strided cloud is stride² sparser, so minPts is divided by that,
   and the stride grows with the image width so larger images cost the same).
3. Each cluster's mean colour (HSV) gives black / red / blue / green.
4. The obstacle rule of seed 004, configurable: the cluster of the obstacle
   colour that is large — by point count (≥ 10000 full-resolution pixels), by
   size (≥ ``min_extent_m`` across), or both. Its axis-aligned box is the box of
   its points together with their foot points on the table (the box stands on
   the table), in the camera frame and in the base frame, plus a margin.
5. Cubes: the cube of known size resting on the table is fitted to the
   cluster's visible surface (robust least squares on the distance to the box
   surface; x, y, yaw in the table plane), so the centre is the cube's centre,
   not the centroid of the faces the camera happens to see.
6. Visibility: a cluster touching the image border is cut by the edge (never a
   pickable cube); a fitted cube whose camera-facing faces are partly hidden by
   something nearer (the depth image sees that nearer surface where the face
   should be) is occluded: pickable while little is hidden, an obstacle beyond
   ``occluded_max_fraction``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import cv2
import numpy as np
from sklearn.cluster import DBSCAN

from services.common.sensors import CameraIntrinsics
from services.common.settings import CubeDetectionSettings
from services.common.settings.vision import DEFAULT_COLOR_TABLE, ColorClassSettings
from services.vision.geometry import (
    Plane,
    backproject,
    project,
    resolution_scale,
    scaled_stride,
    transform_points,
)
from services.vision.lsq import robust_least_squares
from services.vision.results import CubeDetection, ObstacleBox, Visibility

Array = np.ndarray

_MAX_CUBE_POINTS = 300
# below this hidden share a face is whole: single pixels at a face's outline can read the nearer
# neighbour's depth through the sensor's edge blur without anything standing in front
_HIDDEN_NOISE_FRACTION = 0.03
_FACE_SAMPLES = 9  # per side of each face: 81 surface points a face
# A cluster cut by the image edge is the visible part of something larger: reported from a quarter of
# the usual minimum size, so a corner at the edge is not left out of the planning scene.
_EDGE_CLUSTER_DIVISOR = 4


def classify_color(
    mean_rgb: Array,
    black_value_max: int,
    min_saturation: int,
    table: tuple[ColorClassSettings, ...] = DEFAULT_COLOR_TABLE,
) -> str:
    """Colour label of a cluster from its mean RGB (uint8 scale) through HSV and the colour table."""
    px = np.clip(np.rint(np.asarray(mean_rgb, dtype=float)), 0, 255).astype(np.uint8).reshape(1, 1, 3)
    h, s, v = (int(x) for x in cv2.cvtColor(px, cv2.COLOR_RGB2HSV)[0, 0])
    if v <= black_value_max:
        return "black"
    if s < min_saturation:
        return "unknown"
    for colour in table:
        if any(lo <= h < hi for lo, hi in colour.hue_ranges):
            return colour.name
    return "unknown"


def table_frame(plane: Plane) -> Array:
    """T_camera_table: z = table normal (up), origin = foot of the camera on the table."""
    n = plane.normal
    x = np.array([1.0, 0.0, 0.0]) - n[0] * n
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - n[1] * n
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(n, x), n])
    T[:3, 3] = -plane.d * n
    return T


def detect_cubes_and_obstacles(
    color_rgb: Array,
    depth_m: Array,
    intr: CameraIntrinsics,
    plane: Plane,
    params: CubeDetectionSettings,
    T_base_camera: Array | None = None,
    exclude: Array | None = None,
) -> tuple[list[CubeDetection], list[ObstacleBox], list[str], dict[str, float]]:
    """Cubes (centre, colour) and obstacle boxes; notes on clusters that were neither.

    ``exclude``: optional (H, W) bool mask of pixels already explained (e.g. detected rods).
    Returns (cubes, obstacles, notes, timings in ms).
    """
    t0 = time.perf_counter()
    stride = scaled_stride(params.cluster_stride, intr)
    mask = None if exclude is None else ~exclude
    pts, rows, cols = backproject(depth_m, intr, stride, mask, params.min_depth_m, params.max_depth_m)
    h = plane.signed_distance(pts)
    keep = (h > params.plane_residual_m) & (h < params.max_height_m)
    notes: list[str] = []
    if T_base_camera is not None and params.robot_base_radius_m > 0:
        # the arm's own base stands on the table too: it is the robot, not an obstacle in its way
        p_base = transform_points(T_base_camera, pts)
        own = keep & (np.hypot(p_base[:, 0], p_base[:, 1]) < params.robot_base_radius_m)
        if own.any():
            notes.append(f"{int(own.sum())} points on the robot's own base left out")
        keep &= ~own
    pts, rows, cols = pts[keep], rows[keep], cols[keep]
    scale = stride * stride / resolution_scale(intr) ** 2  # one strided point = this many 640-px pixels
    min_samples = max(3, round(params.dbscan_min_points / scale))
    if len(pts) < min_samples:
        return [], [], ["nothing stands on the table"], {"cube_segmentation": _ms(t0)}
    labels = DBSCAN(eps=params.dbscan_eps_m, min_samples=min_samples).fit_predict(pts)
    t1 = time.perf_counter()

    T_cam_table = table_frame(plane)
    T_table_cam = np.linalg.inv(T_cam_table)
    cubes: list[CubeDetection] = []
    found: list[_ObstacleCluster] = []
    rule = params.obstacle
    for k in range(labels.max() + 1):
        sel = labels == k
        n_full = round(np.count_nonzero(sel) * scale)
        if n_full < params.min_cluster_points / _EDGE_CLUSTER_DIVISOR:
            continue
        cut = _visibility(rows[sel], cols[sel], stride, intr) is Visibility.CUT_BY_EDGE
        if n_full < params.min_cluster_points and not cut:
            continue
        cp = pts[sel]
        mean_rgb = color_rgb[rows[sel], cols[sel]].mean(axis=0)
        colour = classify_color(mean_rgb, params.black_value_max, params.min_saturation, params.colors)
        visibility = Visibility.CUT_BY_EDGE if cut else Visibility.WHOLE
        local = transform_points(T_table_cam, cp)
        (cx, cy), sides, angle = cv2.minAreaRect(local[:, :2].astype(np.float32))
        extent = float(max(sides))
        by_points = n_full >= rule.min_points
        by_extent = extent >= rule.min_extent_m
        large = {
            "points": by_points,
            "extent": by_extent,
            "either": by_points or by_extent,
            "both": by_points and by_extent,
        }[rule.require]
        if large and (rule.color == "any" or colour == rule.color):
            found.append(_ObstacleCluster(cp, colour, n_full, mean_rgb, visibility, True))
            continue
        size = params.cube_size_m
        top = float(np.percentile(local[:, 2], 90))
        cube_like = extent <= 1.6 * size and 0.7 * size < top < 1.3 * size
        what = (
            f"{colour} cube cut by the image edge: its centre is unknown, not pickable"
            if cube_like
            else f"{colour} cluster of {n_full} px, {extent * 1000:.0f} mm across and "
            f"{top * 1000:.0f} mm high: neither a cube nor the obstacle"
        )
        if cube_like and visibility is Visibility.WHOLE:
            cube = _fit_cube(local, (cx, cy, np.deg2rad(angle)), size, colour, n_full, T_cam_table, intr)
            hidden = hidden_fraction(cube, size, depth_m, intr, params.occlusion_depth_margin_m)
            if hidden <= params.occluded_max_fraction:
                seen = Visibility.OCCLUDED if hidden > _HIDDEN_NOISE_FRACTION else Visibility.WHOLE
                cubes.append(replace(cube, mean_rgb=mean_rgb, visibility=seen, hidden_fraction=hidden))
                continue
            visibility = Visibility.OCCLUDED
            what = f"{colour} cube {hidden:.0%} hidden by something nearer: its centre is uncertain, not pickable"
        if params.unrecognised_as_obstacles:
            found.append(_ObstacleCluster(cp, colour, n_full, mean_rgb, visibility, False))
            what += "; reported as an obstacle"
        notes.append(what)
    obstacles = [
        _obstacle_box(
            o.points,
            plane,
            o.colour,
            o.n_full,
            intr,
            T_base_camera,
            rule.margin_m,
            o.mean_rgb,
            o.visibility,
            o.recognised,
        )
        for o in _merge_touching(found, plane, rule.margin_m)
    ]
    timings = {"cube_segmentation": (t1 - t0) * 1e3, "cube_pose": _ms(t1)}
    if T_base_camera is not None:
        cubes = [c.in_base(T_base_camera) for c in cubes]
    return cubes, obstacles, notes, timings


@dataclass(frozen=True)
class _ObstacleCluster:
    points: Array  # camera frame
    colour: str
    n_full: int
    mean_rgb: Array
    visibility: Visibility
    recognised: bool


def _merge_touching(found: list[_ObstacleCluster], plane: Plane, margin: float) -> list[_ObstacleCluster]:
    """One obstacle per object: clusters whose boxes (margin included) overlap are one box.

    DBSCAN can split a box seen edge-on; its pieces would each be reported, and a piece is not what the
    planner should avoid, the whole is."""
    out = list(found)
    merged = True
    while merged and len(out) > 1:
        merged = False
        bounds = []
        for o in out:
            solid = np.vstack([o.points, plane.project(o.points)])
            bounds.append((solid.min(axis=0) - margin, solid.max(axis=0) + margin))
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                (lo_i, hi_i), (lo_j, hi_j) = bounds[i], bounds[j]
                if np.all(lo_i <= hi_j) and np.all(lo_j <= hi_i):
                    a, b = out[i], out[j]
                    big = a if (a.recognised, a.n_full) >= (b.recognised, b.n_full) else b
                    n = a.n_full + b.n_full
                    out[i] = _ObstacleCluster(
                        np.vstack([a.points, b.points]),
                        big.colour,
                        n,
                        (a.mean_rgb * a.n_full + b.mean_rgb * b.n_full) / n,
                        max(a.visibility, b.visibility, key=_VISIBILITY_RANK.index),
                        a.recognised or b.recognised,
                    )
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return out


# a merged obstacle is as partial as its most partial piece
_VISIBILITY_RANK = (Visibility.WHOLE, Visibility.OCCLUDED, Visibility.CUT_BY_EDGE)


def _visibility(rows: Array, cols: Array, stride: int, intr: CameraIntrinsics) -> Visibility:
    """Cut by the image edge when the cluster reaches the outermost sampled pixels."""
    edge = stride + 1
    if (
        rows.min() < edge
        or cols.min() < edge
        or rows.max() >= intr.height - edge
        or cols.max() >= intr.width - edge
    ):
        return Visibility.CUT_BY_EDGE
    return Visibility.WHOLE


def _ms(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3


def _box_sdf(q: Array, half: float) -> tuple[Array, Array]:
    """Signed distance of points (cube frame) to an axis-aligned cube's surface, and its gradient."""
    d = np.abs(q) - half
    out = np.maximum(d, 0.0)
    out_norm = np.linalg.norm(out, axis=1)
    inside = out_norm <= 0.0
    k = d.argmax(axis=1)
    sdf = np.where(inside, d[np.arange(len(d)), k], out_norm)
    grad = out / np.maximum(out_norm, 1e-12)[:, None]
    grad[inside] = 0.0
    grad[inside, k[inside]] = 1.0
    return sdf, grad * np.sign(q)


def _fit_cube(
    local: Array,
    init: tuple[float, float, float],
    size: float,
    colour: str,
    n_full: int,
    T_cam_table: Array,
    intr: CameraIntrinsics,
) -> CubeDetection:
    """Cube of known size resting on the table (x, y, yaw) fitted to its visible surface points."""
    half = size / 2.0
    if len(local) > _MAX_CUBE_POINTS:
        local = local[np.linspace(0, len(local) - 1, _MAX_CUBE_POINTS).astype(int)]
    px, py, qz = local[:, 0], local[:, 1], local[:, 2] - half

    def cube_frame(x: Array) -> Array:
        cx, cy, yaw = x
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy = px - cx, py - cy
        return np.column_stack([c * dx + s * dy, -s * dx + c * dy, qz])

    def residuals(x: Array) -> Array:
        return _box_sdf(cube_frame(x), half)[0]

    def jacobian(x: Array) -> Array:
        q = cube_frame(x)
        g = _box_sdf(q, half)[1]
        c, s = np.cos(x[2]), np.sin(x[2])
        return np.column_stack(
            [
                -c * g[:, 0] + s * g[:, 1],  # d/dcx
                -s * g[:, 0] - c * g[:, 1],  # d/dcy
                q[:, 1] * g[:, 0] - q[:, 0] * g[:, 1],  # d/dyaw
            ]
        )

    fit = robust_least_squares(
        residuals,
        np.array(init, dtype=float),
        step=np.array([1e-5, 1e-5, 1e-4]),
        loss_scale=0.003,
        tol=np.array([2e-5, 2e-5, 2e-4]),
        jac=jacobian,
    )
    cx, cy, yaw = fit.x
    res = fit.residuals
    center_table = np.array([cx, cy, half])
    R_table_cube = np.array(
        [[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]]
    )
    center_cam = T_cam_table[:3, :3] @ center_table + T_cam_table[:3, 3]
    return CubeDetection(
        centroid_cam=center_cam,
        color_label=colour,
        n_points=n_full,
        rotation_cam=T_cam_table[:3, :3] @ R_table_cube,
        fit_rms_m=float(np.sqrt(np.mean(np.minimum(np.abs(res), 0.01) ** 2))),
        image_uv=project(center_cam[None], intr)[0],
    )


def hidden_fraction(
    cube: CubeDetection, size: float, depth_m: Array, intr: CameraIntrinsics, margin_m: float
) -> float:
    """Share of the fitted cube's camera-facing surface that something nearer hides.

    Points on the faces that face the camera are projected into the depth image; where the image
    measures a surface more than ``margin_m`` nearer than the face, an object in front hides it. Pixels
    without depth (dropout) and points outside the image say nothing and are not counted."""
    half = size / 2.0
    g = (np.arange(_FACE_SAMPLES) + 0.5) / _FACE_SAMPLES * size - half
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    R, c = cube.rotation_cam, cube.centroid_cam
    hidden = seen = 0
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = sign * R[:, axis]
            centre = c + half * normal
            if normal @ (-centre) <= 0:  # faces away from the camera (or the table underneath)
                continue
            if axis == 2 and sign < 0:
                continue
            e1, e2 = R[:, (axis + 1) % 3], R[:, (axis + 2) % 3]
            pts = centre + u[:, None] * e1 + v[:, None] * e2
            uv = np.rint(project(pts, intr)).astype(int)
            ok = (uv[:, 0] >= 0) & (uv[:, 0] < intr.width) & (uv[:, 1] >= 0) & (uv[:, 1] < intr.height)
            measured = depth_m[uv[ok, 1], uv[ok, 0]]
            expected = pts[ok, 2]
            valid = measured > 0
            hidden += int(np.count_nonzero(valid & (measured < expected - margin_m)))
            seen += int(np.count_nonzero(valid))
    return hidden / seen if seen else 0.0


def _obstacle_box(
    cp: Array,
    plane: Plane,
    colour: str,
    n_full: int,
    intr: CameraIntrinsics,
    T_base_camera: Array | None,
    margin: float,
    mean_rgb: Array | None = None,
    visibility: Visibility = Visibility.WHOLE,
    recognised: bool = True,
) -> ObstacleBox:
    solid = np.vstack([cp, plane.project(cp)])  # the box stands on the table
    lo, hi = solid.min(axis=0) - margin, solid.max(axis=0) + margin
    corners_cam = _box_corners(lo, hi)
    min_base = max_base = None
    if T_base_camera is not None:
        pb = transform_points(T_base_camera, solid)
        min_base, max_base = pb.min(axis=0) - margin, pb.max(axis=0) + margin
        # draw the base-frame box (the one the planner uses) when we have it
        corners_cam = transform_points(np.linalg.inv(T_base_camera), _box_corners(min_base, max_base))
    return ObstacleBox(
        min_cam=lo,
        max_cam=hi,
        n_points=n_full,
        color_label=colour,
        corners_px=project(corners_cam, intr),
        min_base=min_base,
        max_base=max_base,
        mean_rgb=mean_rgb,
        visibility=visibility,
        recognised=recognised,
    )


def _box_corners(lo: Array, hi: Array) -> Array:
    """The 8 corners, index bits (x, y, z) = (4, 2, 1)."""
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
