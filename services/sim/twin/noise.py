"""D435i-like sensor noise for rendered RGB-D (pure numpy/OpenCV; seeded by the caller's Generator).

Depth, in order:
1. range-dependent noise of active stereo: sigma_z = subpixel · z² / (focal_px · baseline)
   (Intel's depth RMS-error formula; ~2.7 mm at 0.8 m, ~0.8 % at 2 m with the defaults);
2. holes on black / shiny surfaces (the hollow black metal rod): a fraction of those pixels lose
   depth, in blobs, as users report for the D435i;
3. flying pixels at depth edges: edge pixels take a depth between the foreground and the
   background, or none;
4. no depth outside the working range. Then quantised to z16 by the caller.
RGB: additive Gaussian noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from services.common.settings import TwinCameraSettings

Array = np.ndarray

HOLE_BLOB_SIGMA_PX = 3.0
# MuJoCo's Phong highlight on the black rod peaks at ~50 above its diffuse level under the twin's
# lights; a colour sensor looking at polished black metal under cell lights records a stripe of
# 100-255 (issue 15). So the camera amplifies what lies above the rod's diffuse level by this gain
# (the nominal highlight strength; randomized per trial in evaluation).
HIGHLIGHT_GAIN = 4.0
EDGE_JUMP_M = 0.015


@dataclass(frozen=True)
class DepthNoiseModel:
    subpixel: float = 0.08
    baseline_m: float = 0.05
    focal_px: float = 383.0
    min_depth_m: float = 0.15
    max_depth_m: float = 4.0
    hole_fraction: float = 0.35
    flying_pixel_fraction: float = 0.5
    edge_dropout_fraction: float = 0.2
    rgb_sigma: float = 2.0

    @classmethod
    def from_settings(cls, cam: TwinCameraSettings) -> DepthNoiseModel:
        return cls(
            subpixel=cam.depth_subpixel,
            baseline_m=cam.stereo_baseline_m,
            focal_px=cam.stereo_focal_px,
            min_depth_m=cam.min_depth_m,
            max_depth_m=cam.max_depth_m,
            hole_fraction=cam.hole_fraction,
            flying_pixel_fraction=cam.flying_pixel_fraction,
            edge_dropout_fraction=cam.edge_dropout_fraction,
            rgb_sigma=cam.rgb_noise_sigma,
        )

    def sigma_m(self, z_m: Array) -> Array:
        return self.subpixel * np.square(z_m) / (self.focal_px * self.baseline_m)


def depth_edges(depth_m: Array, jump_m: float = EDGE_JUMP_M) -> tuple[Array, Array, Array]:
    """(edge mask, local min, local max) over 3×3 neighbourhoods of valid depth."""
    valid = depth_m > 0
    big = np.where(valid, depth_m, np.float32(1e6)).astype(np.float32)
    small = np.where(valid, depth_m, np.float32(0)).astype(np.float32)
    kernel = np.ones((3, 3), np.uint8)
    lo = cv2.erode(big, kernel)
    hi = cv2.dilate(small, kernel)
    edges = valid & (hi - lo > jump_m) & (lo < 1e5)
    return edges, lo, hi


def apply_depth_noise(
    depth_m: Array, hole_mask: Array, model: DepthNoiseModel, rng: np.random.Generator
) -> Array:
    """Noisy depth in metres (float32, 0 = no depth) from clean depth and a mask of hole-prone pixels."""
    z = np.asarray(depth_m, dtype=np.float32)
    valid = z > 0
    out = z + rng.standard_normal(z.shape, dtype=np.float32) * model.sigma_m(z).astype(np.float32)
    # Holes in blobs: threshold smooth noise at the quantile that removes hole_fraction of the mask.
    hole_px = hole_mask & valid
    if model.hole_fraction > 0 and np.any(hole_px):
        field = cv2.GaussianBlur(rng.standard_normal(z.shape, dtype=np.float32), (0, 0), HOLE_BLOB_SIGMA_PX)
        cut = np.quantile(field[hole_px], model.hole_fraction)
        out[hole_px & (field <= cut)] = 0.0
    edges, lo, hi = depth_edges(z)
    if np.any(edges):
        u = rng.random(z.shape, dtype=np.float32)
        flying = edges & (u < model.flying_pixel_fraction)
        mix = rng.random(z.shape, dtype=np.float32)
        out[flying] = (lo + mix * (hi - lo))[flying]
        out[edges & (u >= 1.0 - model.edge_dropout_fraction)] = 0.0
    out[~valid | (out < model.min_depth_m) | (out > model.max_depth_m)] = 0.0
    return out


def apply_rgb_noise(rgb: Array, sigma: float, rng: np.random.Generator) -> Array:
    if sigma <= 0:
        return rgb
    noisy = rgb.astype(np.float32) + rng.standard_normal(rgb.shape, dtype=np.float32) * np.float32(sigma)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def to_z16(depth_m: Array, depth_scale: float) -> Array:
    """Metres → uint16 in units of ``depth_scale`` (0 stays 0, saturates at 65535)."""
    return np.clip(np.rint(np.asarray(depth_m, dtype=np.float64) / depth_scale), 0, 65535).astype(np.uint16)
