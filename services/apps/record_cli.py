"""The live view and recording wired into a cell, ``pickplace serve record``, and ``pickplace replay FILE.mcap``.

- :func:`cell_live_view`: in ``pickplace up``, the Foxglove server and the recorder on the cell's bus, fed
  in-process with the frames vision detects on (the twin camera is not on the bus there) and the driver's
  status (mode, alarms);
- :func:`serve_record`: the same as its own service on the bus (``pickplace serve record``), frames from
  the frame stream, robot status over gRPC;
- ``pickplace replay``: a recording back into Foxglove (recorded speed or ``--fast``) and into the vision
  pipeline: every recorded frame is detected again and compared with the detections recorded with it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from pickplace.v1 import robot_pb2
from rich.console import Console
from rich.table import Table

from services.common.errors import ConfigurationError, InvalidInputError
from services.common.settings import Settings
from services.record.replay import (
    Decoder,
    DetectionComparison,
    FrameAssembler,
    compare_detections,
    iter_messages,
    open_recording,
    recorded_detections,
)
from services.record.service import RecordService

if TYPE_CHECKING:
    from services.apps.cell import Cell
    from services.robot.service import RobotService
    from services.vision.service import VisionService

app = typer.Typer(no_args_is_help=True)
console = Console()
log = logging.getLogger("pickplace.record.cli")

FRAME_TOPICS = ("/camera/color", "/camera/depth", "/camera/calibration", "/tf")


def record_overrides(foxglove_port: int | None, no_foxglove: bool, record: str | None) -> dict[str, Any]:
    """The ``record`` settings section the ``up``/``serve`` options ask for (empty: the config's own)."""
    fox: dict[str, Any] = {}
    if foxglove_port is not None:
        fox["port"] = foxglove_port
    if no_foxglove:
        fox["enabled"] = False
    out: dict[str, Any] = {"foxglove": fox} if fox else {}
    if record:
        out["dir"] = str(Path(record).resolve())
    return out


# ---------------------------------------------------------------------------- in a cell
def driver_status(robot: RobotService) -> Callable[[], Any]:
    """The robot's status from the driver itself: mode, e-stop, gripper and (in error) the alarm list."""
    from services.robot.messages import robot_status_msg

    async def status() -> robot_pb2.RobotStatus:
        d = robot.driver
        fb = d.client.feedback
        alarms: list[int] = []
        if fb is not None and fb.in_error:
            alarms, _ = await d.client.describe_alarms()
        return robot_status_msg(fb, d.spec, fb is not None, alarms, d.gripper.state().closed)

    return status


def tap_vision(vision: VisionService, view: RecordService) -> Callable[[], None]:
    """Hand every frame vision detects on (and the calibration it uses) to the view; returns the undo."""
    pipeline = vision.pipeline
    inner = pipeline.detect

    def detect(frame: Any, T_base_camera: Any = None) -> Any:
        view.offer_frame(frame, T_base_camera)
        return inner(frame, T_base_camera)

    setattr(pipeline, "detect", detect)  # noqa: B010 — an instance attribute over the method, undone on exit
    return lambda: pipeline.__dict__.pop("detect", None)


@contextlib.asynccontextmanager
async def cell_live_view(cell: Cell, console: Console) -> AsyncIterator[RecordService | None]:
    s = cell.settings
    if not (s.record.foxglove.enabled or s.record.dir):
        yield None
        return
    assert cell.robot is not None and cell.vision is not None
    view = RecordService(
        s, cell.bus, T_base_camera=cell.vision.T_base_camera, robot_status=driver_status(cell.robot)
    )
    async with view:
        undo_vision = tap_vision(cell.vision, view)  # the plans come on the bus (the task publishes them)
        try:
            if view.live:
                console.print(
                    f"Foxglove live view: [link]ws://{s.record.foxglove.host}:{view.port}[/link] "
                    "(layout: deploy/foxglove/pickplace-layout.json)"
                )
            if view.recorder is not None:
                console.print(f"recording MCAP under {view.record_dir}")
            yield view
        finally:
            undo_vision()


async def serve_record(settings: Settings) -> None:
    """``pickplace serve record``: the live view / recorder of a cell whose services run elsewhere."""
    from pickplace.v1 import robot_pb2_grpc

    from services.common.bus import Bus
    from services.common.camera_pose import load_T_base_camera
    from services.common.grpc_util import cell_token, channel

    T, _source = load_T_base_camera(settings.vision.calibration)
    ch = channel(settings.grpc.client_host("robot"), settings.grpc.robot_port, cell_token(settings))
    stub = robot_pb2_grpc.RobotControllerStub(ch)

    async def status() -> robot_pb2.RobotStatus:
        return await stub.GetStatus(robot_pb2.GetStatusRequest(), timeout=settings.grpc.request_timeout_s)

    async with (
        ch,
        Bus(settings.zenoh) as bus,
        RecordService(settings, bus, T_base_camera=T, robot_status=status) as view,
    ):
        await view.wait()


# ---------------------------------------------------------------------------- replay
@dataclass
class ReplayReport:
    messages: int = 0
    frames: int = 0
    comparisons: list[DetectionComparison] = field(default_factory=list)
    tolerance_m: float = 0.01

    @property
    def ok(self) -> bool:
        return all(c.within(self.tolerance_m) for c in self.comparisons)


async def run_replay(
    settings: Settings,
    path: Path,
    *,
    fast: bool = False,
    live: bool = True,
    detect: bool = True,
    tolerance_m: float = 0.01,
    out: Console | None = None,
    on_server: Callable[[int], None] | None = None,
) -> ReplayReport:
    """Play ``path`` into a Foxglove server (when ``live``) and its frames into the vision pipeline."""
    import foxglove

    from services.vision.messages import detections_msg
    from services.vision.pipeline import VisionPipeline

    out = out or console
    rec = open_recording(path)
    out.print(
        f"{path}: {sum(rec.counts.values())} messages over {rec.duration_s:.1f} s on {len(rec.counts)} channels"
    )
    report = ReplayReport(tolerance_m=tolerance_m)
    recorded = recorded_detections(path) if detect else {}
    pipeline = VisionPipeline(settings.vision) if detect else None
    assembler, decoder = FrameAssembler(), Decoder()
    channels: dict[str, foxglove.Channel] = {}
    ctx = foxglove.Context()
    server = None
    if live:
        fs = settings.record.foxglove
        try:
            server = foxglove.start_server(
                name=f"pickplace replay {path.name}", host=fs.host, port=fs.port, context=ctx
            )
        except RuntimeError as exc:  # the SDK's FoxgloveError: the port is taken (a running cell's view?)
            raise ConfigurationError(
                f"cannot serve the replay on {fs.host}:{fs.port}: {exc} (--foxglove-port N, or --no-foxglove)"
            ) from exc
        out.print(
            f"Foxglove: ws://{fs.host}:{server.port} ({'as fast as possible' if fast else 'recorded speed'})"
        )
        if on_server is not None:
            on_server(server.port)
    try:
        t0_wall = time.monotonic()
        for msg in iter_messages(path):
            if not fast:  # replay pacing: the recording's own timeline against this machine's clock
                due = (msg.log_time_ns - rec.start_ns) / 1e9 - (time.monotonic() - t0_wall)
                if due > 0:
                    await asyncio.sleep(due)
            report.messages += 1
            if live:
                ch = channels.get(msg.topic)
                if ch is None and msg.schema is not None:
                    schema = foxglove.Schema(
                        name=msg.schema.name, encoding=msg.schema.encoding, data=msg.schema.data
                    )
                    ch = channels[msg.topic] = foxglove.Channel(
                        msg.topic, schema=schema, message_encoding=msg.message_encoding, context=ctx
                    )
                if ch is not None:
                    ch.log(msg.data, log_time=msg.log_time_ns)
            if pipeline is not None and msg.topic in FRAME_TOPICS:
                frame = assembler.add(msg.topic, decoder.decode(msg))
                if frame is None:
                    continue
                report.frames += 1
                if frame.stamp_ns in recorded:
                    result = await asyncio.to_thread(pipeline.detect, frame, assembler.T_base_camera)
                    again = detections_msg(result, frame.frame_id)
                    report.comparisons.append(compare_detections(recorded[frame.stamp_ns], again))
    finally:
        if server is not None:
            server.stop()
    _print_report(report, out)
    return report


def _print_report(report: ReplayReport, out: Console) -> None:
    t = Table(title="replay")
    t.add_column("frame stamp (ns)")
    t.add_column("recorded vs re-detected")
    t.add_column(f"within {1000 * report.tolerance_m:.0f} mm")
    for c in report.comparisons:
        t.add_row(str(c.stamp_ns), c.describe(), "yes" if c.within(report.tolerance_m) else "[red]NO[/red]")
    out.print(t)
    out.print(
        f"{report.messages} messages replayed, {report.frames} frames, {len(report.comparisons)} re-detected"
    )


ProfileOpt = Annotated[str | None, typer.Option("--profile", "-p", help="config profile (sim, nova5-real)")]


@app.command("replay")
def replay(
    file: Annotated[Path, typer.Argument(help="an MCAP file written by `pickplace up --record DIR`")],
    fast: Annotated[bool, typer.Option("--fast", help="as fast as possible, not at recorded speed")] = False,
    foxglove_port: Annotated[int | None, typer.Option("--foxglove-port", help="Foxglove server port")] = None,
    no_foxglove: Annotated[bool, typer.Option("--no-foxglove", help="no Foxglove server")] = False,
    detect: Annotated[
        bool, typer.Option("--detect/--no-detect", help="re-detect the recorded frames")
    ] = True,
    tolerance_mm: Annotated[float, typer.Option(help="largest recorded vs re-detected distance")] = 10.0,
    profile: ProfileOpt = None,
) -> None:
    """Play a recording back into Foxglove and into the vision pipeline (re-detect and compare)."""
    from services.apps.cli import _run, _settings

    s = _settings(profile, None, console_log=False, record=record_overrides(foxglove_port, no_foxglove, None))
    try:
        open_recording(file)
    except InvalidInputError as exc:
        console.print(f"[red]cannot replay:[/red] {exc}", soft_wrap=True)
        raise typer.Exit(2) from None
    report = _run(
        run_replay(s, file, fast=fast, live=not no_foxglove, detect=detect, tolerance_m=tolerance_mm / 1000)
    )
    if report is not None and not report.ok:
        raise typer.Exit(1)
