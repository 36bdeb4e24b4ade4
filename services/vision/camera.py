"""The camera interface: every RGB-D source (RealSense, the twin, replay) yields RGBDFrame."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from services.common.errors import InvalidInputError


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the colour stream (depth is aligned to it)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def validate(self) -> CameraIntrinsics:
        vals = np.array([self.fx, self.fy, self.cx, self.cy], dtype=float)
        if not np.all(np.isfinite(vals)) or self.fx <= 0 or self.fy <= 0:
            raise InvalidInputError(
                f"camera intrinsics are invalid: fx={self.fx} fy={self.fy} cx={self.cx} cy={self.cy}"
            )
        if self.width <= 0 or self.height <= 0:
            raise InvalidInputError(f"camera size must be positive, got {self.width}x{self.height}")
        return self


@dataclass(frozen=True)
class RGBDFrame:
    """One aligned RGB-D frame.

    ``color``: (H, W, 3) uint8 RGB. ``depth``: (H, W) uint16 in units of ``depth_scale`` metres
    (RealSense z16; 0 = no depth). Depth is along the optical axis (z), aligned to colour.
    """

    color: np.ndarray
    depth: np.ndarray
    intrinsics: CameraIntrinsics
    depth_scale: float = 0.001
    stamp_ns: int = 0
    frame_id: str = "camera"
    seq: int = 0
    meta: dict[str, object] = field(default_factory=dict)

    def depth_m(self) -> np.ndarray:
        return self.depth.astype(np.float32) * np.float32(self.depth_scale)

    def validate(self) -> RGBDFrame:
        intr = self.intrinsics.validate()
        shape = (intr.height, intr.width)
        if self.color.shape != (*shape, 3) or self.color.dtype != np.uint8:
            raise InvalidInputError(
                f"colour image must be uint8 {shape[0]}x{shape[1]}x3, "
                f"got {self.color.dtype} {self.color.shape}"
            )
        if self.depth.shape != shape:
            raise InvalidInputError(f"depth image must be {shape[0]}x{shape[1]}, got {self.depth.shape}")
        if not (np.isfinite(self.depth_scale) and self.depth_scale > 0):
            raise InvalidInputError(f"depth_scale must be a positive number, got {self.depth_scale}")
        return self


@runtime_checkable
class Camera(Protocol):
    """An RGB-D source. Implementations: RealSense D435i, the twin's simulated RealSense, replay."""

    @property
    def intrinsics(self) -> CameraIntrinsics: ...

    def capture(self) -> RGBDFrame:
        """Return the newest aligned frame (blocking at most the source's frame period)."""
        ...

    def close(self) -> None: ...
