"""Typer commands of the vision area, for the ``pickplace`` app to mount (``app.add_typer(vision_cli.app)``).

- ``vision-detect``: run the pipeline on recorded frames (a ``record`` or ``sim-scene`` directory);
- ``record``: capture a replayable frame set from a camera source (seed 001's dataset collection);

The calibration commands are in ``calibration_cli``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from services.common.errors import (
    ConfigurationError,
    RobotError,
)
from services.common.sensors import Camera
from services.common.settings import REPO_ROOT, Settings, load_settings

if TYPE_CHECKING:
    from services.vision.results import DetectionResult

app = typer.Typer(
    help="Vision: detect on recordings, record frames, calibrate the camera.", no_args_is_help=True
)
console = Console()

ProfileOpt = Annotated[str | None, typer.Option("--profile", "-p", help="config profile (sim, nova5-real)")]
SourceOpt = Annotated[
    str, typer.Option("--source", help="camera: realsense | replay | bus | twin (default: settings)")
]


def _settings(profile: str | None) -> Settings:
    try:
        return load_settings(profile)
    except ConfigurationError as exc:
        console.print(f"[red]configuration error:[/red] {exc}", soft_wrap=True)
        raise typer.Exit(2) from None


def _calibration_path(settings: Settings, out: Path | None) -> Path:
    path = out or Path(settings.vision.calibration.file)
    return path if path.is_absolute() else REPO_ROOT / path


@contextlib.contextmanager
def open_camera(settings: Settings, source: str = "", seed: int = 0) -> Iterator[Camera]:
    """A camera for CLI use; closed on exit. ``bus`` reads the Zenoh frame stream."""
    from services.vision.service import BusCamera, make_camera

    src = source or settings.vision.camera.source
    if src == "bus":
        from services.common.bus import Bus
        from services.common.keys import CellKeys

        with Bus(settings.zenoh) as bus:
            cam = BusCamera(bus, CellKeys(settings.cell_id).camera_frames)
            try:
                yield cam
            finally:
                cam.close()
        return
    if src == "twin":
        from services.sim.twin.camera import TwinCamera
        from services.sim.twin.engine import create_twin_engine

        engine = create_twin_engine(settings, seed)
        twin_cam = TwinCamera(engine, seed=seed)
        try:
            engine.settle(0.3)
            yield twin_cam
        finally:
            twin_cam.close()
            engine.close()
        return
    cam_settings = settings.vision.camera.model_copy(update={"source": src})
    made = make_camera(cam_settings)
    if made is None:
        raise ConfigurationError(f"unknown camera source {src!r}: realsense, replay, bus or twin")
    try:
        yield made
    finally:
        made.close()


def _fail(exc: RobotError) -> typer.Exit:
    console.print(f"[red]{type(exc).__name__}:[/red] {exc}", soft_wrap=True)
    return typer.Exit(1)


# --- detect on recordings ------------------------------------------------------------------------
@app.command("vision-detect")
def vision_detect(
    replay: Annotated[Path, typer.Argument(help="recorded frame directory (record or sim-scene output)")],
    frames: Annotated[int, typer.Option(min=1, help="how many frames to process")] = 1,
    overlay: Annotated[Path | None, typer.Option(help="write the last frame's debug overlay (JPEG)")] = None,
    profile: ProfileOpt = None,
) -> None:
    """Detect rods, cubes and obstacles on recorded frames and print them."""
    from services.common.camera_pose import load_T_base_camera
    from services.vision.overlay import overlay_jpeg
    from services.vision.pipeline import VisionPipeline
    from services.vision.replay import ReplayCamera

    s = _settings(profile)
    try:
        T, source = load_T_base_camera(s.vision.calibration)
        cam = ReplayCamera(replay, loop=False)
        pipe = VisionPipeline(s.vision)
        console.print(f"calibration: {source}")
        for _ in range(min(frames, len(cam))):
            frame = cam.capture()
            result = pipe.detect(frame, T)
            _print_result(result, frame.seq)
        if overlay is not None:
            overlay.write_bytes(overlay_jpeg(frame.color, result, s.vision.debug_jpeg_quality))
            console.print(f"overlay written to {overlay}")
    except RobotError as exc:
        raise _fail(exc) from None


def _print_result(result: DetectionResult, seq: int) -> None:
    table = Table(title=f"frame {seq}: {result.timings_ms.get('total', 0):.1f} ms")
    for col in ("object", "frame", "x (m)", "y (m)", "z (m)", "details"):
        table.add_column(col)
    for k, rod in enumerate(result.rods, start=1):
        frame_name, p = (
            ("base", rod.center_base) if rod.center_base is not None else ("camera", rod.center_cam)
        )
        table.add_row(
            f"rod #{k}",
            frame_name,
            *(f"{v:.4f}" for v in p),
            f"conf {rod.confidence:.2f}, L {rod.length_m * 1e3:.0f} mm, {rod.method}",
        )
    for cube in result.cubes:
        frame_name, p = (
            ("base", cube.centroid_base) if cube.centroid_base is not None else ("camera", cube.centroid_cam)
        )
        table.add_row(f"{cube.color_label} cube", frame_name, *(f"{v:.4f}" for v in p), f"{cube.n_points} px")
    for box in result.obstacles:
        frame_name, lo, hi = (
            ("base", box.min_base, box.max_base)
            if box.min_base is not None and box.max_base is not None
            else ("camera", box.min_cam, box.max_cam)
        )
        table.add_row(
            "obstacle",
            frame_name,
            *(f"{a:.3f}..{b:.3f}" for a, b in zip(lo, hi, strict=True)),
            box.color_label,
        )
    console.print(table)
    for note in result.notes:
        console.print(f"  [dim]{note}[/dim]")


# --- record --------------------------------------------------------------------------------------
@app.command("record")
def record(
    out: Annotated[Path, typer.Option("--out", help="empty directory for the frame set")],
    frames: Annotated[int, typer.Option(min=1, max=100000)] = 30,
    period_s: Annotated[float, typer.Option(min=0.0, help="seconds between frames (0 = as possible)")] = 0.0,
    source: SourceOpt = "",
    seed: Annotated[int, typer.Option(min=0, help="scene seed for --source twin")] = 0,
    profile: ProfileOpt = None,
) -> None:
    """Capture a replayable RGB-D frame set (+ intrinsics) from a camera source."""
    from services.vision.replay import record_frames

    s = _settings(profile)
    try:
        with open_camera(s, source, seed) as cam, Progress(console=console) as bar:
            task = bar.add_task("recording", total=frames)
            record_frames(cam, out, frames, period_s, lambda done, _total: bar.update(task, completed=done))
    except RobotError as exc:
        raise _fail(exc) from None
    console.print(f"recorded {frames} frame(s) into {out}")
