"""The D435i-like noise model on synthetic depth (pure numpy, seeded)."""

from __future__ import annotations

import numpy as np
import pytest

from services.sim.twin.noise import (
    DepthNoiseModel,
    apply_depth_noise,
    apply_rgb_noise,
    depth_edges,
    to_z16,
)

H, W = 120, 160


def step_scene() -> tuple[np.ndarray, np.ndarray]:
    """A plane at 1.0 m with a raised block at 0.9 m; the block is hole-prone (black)."""
    depth = np.full((H, W), 1.0, dtype=np.float32)
    depth[40:80, 60:100] = 0.9
    mask = np.zeros((H, W), dtype=bool)
    mask[40:80, 60:100] = True
    return depth, mask


def test_range_noise_follows_the_stereo_formula() -> None:
    model = DepthNoiseModel(hole_fraction=0.0, flying_pixel_fraction=0.0, edge_dropout_fraction=0.0)
    for z in (0.5, 1.0, 2.0):
        depth = np.full((200, 200), z, dtype=np.float32)
        out = apply_depth_noise(depth, np.zeros_like(depth, bool), model, np.random.default_rng(0))
        expected = model.subpixel * z**2 / (model.focal_px * model.baseline_m)
        assert np.std(out - z) == pytest.approx(expected, rel=0.05)
        assert abs(np.mean(out - z)) < 3 * expected / 200
    assert model.sigma_m(np.array(2.0)) / 2.0 < 0.02  # within the datasheet's ≤ 2 % at 2 m


def test_holes_only_on_hole_prone_pixels_in_the_requested_fraction() -> None:
    depth, mask = step_scene()
    model = DepthNoiseModel(hole_fraction=0.35, flying_pixel_fraction=0.0, edge_dropout_fraction=0.0)
    out = apply_depth_noise(depth, mask, model, np.random.default_rng(3))
    holes = out == 0
    assert holes[mask].mean() == pytest.approx(0.35, abs=0.02)
    assert not holes[~mask].any()


def test_flying_pixels_and_dropouts_only_at_depth_edges() -> None:
    depth, mask = step_scene()
    model = DepthNoiseModel(
        subpixel=0.0, hole_fraction=0.0, flying_pixel_fraction=0.6, edge_dropout_fraction=0.3
    )
    out = apply_depth_noise(depth, mask, model, np.random.default_rng(5))
    edges, _, _ = depth_edges(depth)
    changed = out != depth
    assert changed.any() and not changed[~edges].any()
    mixed = changed & (out > 0)
    assert np.all((out[mixed] >= 0.9 - 1e-6) & (out[mixed] <= 1.0 + 1e-6))  # between fore- and background
    assert (out[edges] == 0).mean() == pytest.approx(0.3, abs=0.1)


def test_out_of_range_and_missing_depth_read_zero() -> None:
    model = DepthNoiseModel(
        subpixel=0.0,
        min_depth_m=0.2,
        max_depth_m=3.0,
        hole_fraction=0.0,
        flying_pixel_fraction=0.0,
        edge_dropout_fraction=0.0,
    )
    depth = np.array([[0.0, 0.1, 1.0, 5.0]], dtype=np.float32)
    out = apply_depth_noise(depth, np.zeros_like(depth, bool), model, np.random.default_rng(0))
    assert out.tolist() == [[0.0, 0.0, 1.0, 0.0]]


def test_noise_is_seeded() -> None:
    depth, mask = step_scene()
    model = DepthNoiseModel()
    a = apply_depth_noise(depth, mask, model, np.random.default_rng(9))
    b = apply_depth_noise(depth, mask, model, np.random.default_rng(9))
    c = apply_depth_noise(depth, mask, model, np.random.default_rng(10))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_rgb_noise_and_z16_quantisation() -> None:
    rgb = np.full((50, 50, 3), 128, np.uint8)
    assert apply_rgb_noise(rgb, 0.0, np.random.default_rng(0)) is rgb
    noisy = apply_rgb_noise(rgb, 4.0, np.random.default_rng(0))
    assert noisy.dtype == np.uint8 and np.std(noisy.astype(float)) == pytest.approx(4.0, rel=0.1)
    saturated = apply_rgb_noise(np.full((10, 10, 3), 255, np.uint8), 10.0, np.random.default_rng(0))
    assert saturated.max() == 255
    z = to_z16(np.array([0.0, 0.0004, 0.0006, 1.2345, 100.0]), 0.001)
    assert z.dtype == np.uint16 and z.tolist() == [0, 0, 1, 1234, 65535]
