"""Recorded RGB-D frames: the replay camera and the recorder (`pickplace record`).

Directory layout (the same as the twin's ``write_sim_scene``, so its frame sets replay too):

- ``color_000.png`` — 8-bit colour (stored BGR by OpenCV), ``depth_000.png`` — 16-bit depth in
  units of ``depth_scale`` metres, one pair per frame, numbered from 0;
- ``intrinsics.json`` — ``width, height, fx, fy, cx, cy, distortion, depth_scale``;
- optional ``ground_truth.json`` (evaluation only; the replay camera exposes it, never the cores).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from services.common.errors import CameraConnectionError, InvalidInputError
from services.common.sensors import Camera, CameraIntrinsics, RGBDFrame, write_intrinsics

_INDEX = re.compile(r"^(color|depth)_(\d+)\.png$")


def read_intrinsics(directory: Path) -> tuple[CameraIntrinsics, float]:
    path = directory / "intrinsics.json"
    try:
        raw = json.loads(path.read_text())
        intr = CameraIntrinsics(
            width=int(raw["width"]),
            height=int(raw["height"]),
            fx=float(raw["fx"]),
            fy=float(raw["fy"]),
            cx=float(raw["cx"]),
            cy=float(raw["cy"]),
            distortion=tuple(float(v) for v in raw.get("distortion", ())),
        )
        scale = float(raw.get("depth_scale", 0.001))
    except FileNotFoundError as exc:
        raise CameraConnectionError(f"replay directory {directory} has no intrinsics.json") from exc
    except (KeyError, TypeError, ValueError) as exc:
        raise CameraConnectionError(f"replay intrinsics {path} are malformed: {exc}") from exc
    return intr.validate(), scale


class ReplayCamera:
    """Serves a recorded directory frame by frame (looping, or ending with CameraConnectionError)."""

    def __init__(self, directory: str | Path, loop: bool = True):
        self.directory = Path(directory)
        if not self.directory.is_dir():
            raise CameraConnectionError(f"replay directory {self.directory} does not exist")
        self._intr, self._depth_scale = read_intrinsics(self.directory)
        pairs: dict[int, dict[str, Path]] = {}
        for p in self.directory.iterdir():
            m = _INDEX.match(p.name)
            if m:
                pairs.setdefault(int(m.group(2)), {})[m.group(1)] = p
        self._files = [(v["color"], v["depth"]) for k, v in sorted(pairs.items()) if len(v) == 2]
        if not self._files:
            raise CameraConnectionError(
                f"replay directory {self.directory} has no color_N.png/depth_N.png pairs"
            )
        self.loop = loop
        self._next = 0
        self._seq = 0
        self._closed = False
        gt = self.directory / "ground_truth.json"
        self.ground_truth: dict[str, Any] | None = json.loads(gt.read_text()) if gt.exists() else None

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intr

    def __len__(self) -> int:
        return len(self._files)

    def capture(self) -> RGBDFrame:
        if self._closed:
            raise CameraConnectionError("replay camera is closed")
        if self._next >= len(self._files):
            if not self.loop:
                raise CameraConnectionError(
                    f"end of the recording in {self.directory} ({len(self._files)} frames)"
                )
            self._next = 0
        color_path, depth_path = self._files[self._next]
        self._next += 1
        bgr = cv2.imread(str(color_path), cv2.IMREAD_COLOR)
        depth = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)
        if bgr is None or depth is None:
            raise CameraConnectionError(f"unreadable recorded frame {color_path.name}/{depth_path.name}")
        if depth.dtype != np.uint16:
            raise CameraConnectionError(f"{depth_path.name} must be a 16-bit PNG, got {depth.dtype}")
        self._seq += 1
        return RGBDFrame(
            color=cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
            depth=depth,
            intrinsics=self._intr,
            depth_scale=self._depth_scale,
            stamp_ns=time.time_ns(),
            frame_id="camera",
            seq=self._seq,
        ).validate()

    def close(self) -> None:
        self._closed = True


def record_frames(
    camera: Camera,
    out_dir: str | Path,
    n_frames: int,
    period_s: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Capture ``n_frames`` from any camera into a replayable directory (seed 001's dataset collection)."""
    if n_frames < 1:
        raise InvalidInputError(f"record at least one frame, got {n_frames}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if any(_INDEX.match(p.name) for p in out.iterdir()):
        raise InvalidInputError(f"{out} already holds recorded frames; choose an empty directory")
    width = max(3, len(str(n_frames - 1)))
    first: RGBDFrame | None = None
    for i in range(n_frames):
        t0 = time.monotonic()
        frame = camera.capture().validate()
        if first is None:
            first = frame
            write_intrinsics(out, frame.intrinsics, frame.depth_scale)
        elif frame.intrinsics != first.intrinsics:
            raise InvalidInputError("camera intrinsics changed during the recording")
        depth = np.asarray(frame.depth)
        if depth.dtype != np.uint16:
            raise InvalidInputError(f"recording needs uint16 depth, got {depth.dtype}")
        ok_c = cv2.imwrite(
            str(out / f"color_{i:0{width}d}.png"), cv2.cvtColor(frame.color, cv2.COLOR_RGB2BGR)
        )
        ok_d = cv2.imwrite(str(out / f"depth_{i:0{width}d}.png"), depth)
        if not (ok_c and ok_d):
            raise InvalidInputError(f"could not write frame {i} into {out}")
        if progress is not None:
            progress(i + 1, n_frames)
        if period_s > 0:
            time.sleep(max(0.0, period_s - (time.monotonic() - t0)))
    return out
