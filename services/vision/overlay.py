"""Debug image for the dashboard: detections drawn on the colour frame, JPEG-encoded."""

from __future__ import annotations

import cv2
import numpy as np

from services.common.errors import InvalidInputError
from services.vision.results import DetectionResult

Array = np.ndarray

_LABEL_BGR = {
    "red": (40, 40, 230),
    "green": (60, 200, 60),
    "blue": (230, 120, 40),
    "black": (200, 200, 200),
    "unknown": (0, 200, 255),
}
_ROD_BGR = (0, 255, 255)
_OBSTACLE_BGR = (255, 0, 255)
_BOX_EDGES = [(0, 1), (0, 2), (1, 3), (2, 3), (4, 5), (4, 6), (5, 7), (6, 7), (0, 4), (1, 5), (2, 6), (3, 7)]


def draw_detections(color_rgb: Array, result: DetectionResult) -> Array:
    """A BGR copy of the frame with rods (axis, ends, rank, confidence), cubes and obstacle boxes."""
    if color_rgb.ndim != 3 or color_rgb.shape[2] != 3 or color_rgb.dtype != np.uint8:
        raise InvalidInputError(
            f"overlay needs an (H, W, 3) uint8 image, got {color_rgb.dtype} {color_rgb.shape}"
        )
    img = cv2.cvtColor(color_rgb, cv2.COLOR_RGB2BGR)
    for rank, rod in enumerate(result.rods, start=1):
        (u0, v0), (u1, v1) = _pt(rod.endpoints_px[0]), _pt(rod.endpoints_px[1])
        cv2.line(img, (u0, v0), (u1, v1), _ROD_BGR, 2, cv2.LINE_AA)
        for p in ((u0, v0), (u1, v1)):
            cv2.circle(img, p, 4, _ROD_BGR, -1, cv2.LINE_AA)
        mid = ((u0 + u1) // 2, (v0 + v1) // 2)
        cv2.drawMarker(img, mid, (0, 0, 255), cv2.MARKER_CROSS, 12, 2)
        where = rod.center_base if rod.center_base is not None else rod.center_cam
        frame_name = "base" if rod.center_base is not None else "cam"
        text = f"rod#{rank} {rod.confidence:.2f} {frame_name} ({where[0]:.3f},{where[1]:.3f},{where[2]:.3f})"
        _label(img, text, (mid[0] + 8, mid[1] - 8), _ROD_BGR)
    for cube in result.cubes:
        u, v = _pt(cube.image_uv)
        colour = _LABEL_BGR.get(cube.color_label, _LABEL_BGR["unknown"])
        cv2.circle(img, (u, v), 6, colour, 2, cv2.LINE_AA)
        _label(img, cube.color_label, (u + 8, v + 4), colour)
    for box in result.obstacles:
        pts = [_pt(p) for p in box.corners_px]
        for a, b in _BOX_EDGES:
            cv2.line(img, pts[a], pts[b], _OBSTACLE_BGR, 1, cv2.LINE_AA)
        _label(img, "obstacle", pts[0], _OBSTACLE_BGR)
    if not result.rods and result.notes:
        _label(img, result.notes[0][:90], (8, img.shape[0] - 10), (0, 0, 255))
    total = result.timings_ms.get("total")
    if total is not None:
        _label(img, f"{total:.1f} ms", (8, 18), (255, 255, 255))
    return img


def encode_jpeg(image_bgr: Array, quality: int = 80) -> bytes:
    if not 1 <= quality <= 100:
        raise InvalidInputError(f"JPEG quality must be within 1-100, got {quality}")
    ok, buf = cv2.imencode(".jpg", image_bgr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise InvalidInputError(f"could not JPEG-encode an image of shape {image_bgr.shape}")
    return buf.tobytes()


def overlay_jpeg(color_rgb: Array, result: DetectionResult, quality: int = 80) -> bytes:
    return encode_jpeg(draw_detections(color_rgb, result), quality)


def _pt(p: Array) -> tuple[int, int]:
    q = np.nan_to_num(np.asarray(p, dtype=float), nan=-1.0, posinf=-1.0, neginf=-1.0)
    q = np.clip(q, -1e5, 1e5)
    r = np.rint(q).astype(int)
    return int(r[0]), int(r[1])


def _label(img: Array, text: str, org: tuple[int, int], colour: tuple[int, int, int]) -> None:
    """Text on a dark box, so it stays legible on any background after JPEG compression."""
    font, scale = cv2.FONT_HERSHEY_SIMPLEX, 0.42
    (w, h), base = cv2.getTextSize(text, font, scale, 1)
    x = int(np.clip(org[0], 0, max(img.shape[1] - w - 2, 0)))
    y = int(np.clip(org[1], h + 2, img.shape[0] - base - 1))
    cv2.rectangle(img, (x - 2, y - h - 2), (x + w + 2, y + base), (0, 0, 0), -1)
    cv2.putText(img, text, (x, y), font, scale, colour, 1, cv2.LINE_AA)
