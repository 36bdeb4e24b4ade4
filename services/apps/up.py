"""``pickplace up``: the whole cell in one process on the embedded defaults.

The simulated Nova5 twin behind the Dobot protocol, the simulated RealSense, the
vision, grasp, motion, robot-driver and task services on loopback, and a live
terminal display of the pick cycle (state, cycles, success rate, cycle time) with
a summary when it stops. ``job="keypose"`` runs seed 003's key-pose cycle on the
kinematic simulator instead (no vision, no objects).

A UR model (``robot.model: ur5e | ur3``) runs on a simulated UR e-Series through ur_rtde instead of the
simulated Dobot (the driver ``ur_rtde`` is selected for it): the pick cell on the UR twin
(:class:`services.apps.cell.Cell`), and the key-pose job with seed 003's own poses and 2 s dwell
(``config/robots/ur3-keypose.yaml``'s cycle, unless a cycle is configured).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import time
from collections.abc import AsyncIterator, Callable

from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

from services.apps.cell import Cell, is_ur
from services.apps.record_cli import cell_live_view
from services.common.bus import Bus
from services.common.sensors import Camera, CameraIntrinsics, RGBDFrame
from services.common.settings import Settings, load_settings
from services.common.settings.loader import CONFIG_DIR
from services.common.settings.robot import KeyPoseCycleSettings
from services.robot.demo_cycle import CycleEvent, CycleReport, run_keypose_cycle
from services.robot.service import RobotService
from services.sim.app import build_sim_server
from services.task.states import PickOutcome, TaskCounters

log = logging.getLogger("pickplace.app")

SEED_003_CYCLE = CONFIG_DIR / "robots" / "ur3-keypose.yaml"  # seed 003's key poses (a UR's) and dwell


async def run_all_in_one(
    settings: Settings,
    cycles: int = 0,
    engine: str | None = None,
    console: Console | None = None,
    job: str = "pick",
) -> object:
    console = console or Console()
    if job == "keypose":
        return await run_keypose_demo(settings, cycles or 2, engine or "kinematic", console)
    return await run_pick_cell(settings, cycles, console)


# ---------------------------------------------------------------------------- the pick cell
def _status_table(runner, started: float, last: PickOutcome | None) -> Group:  # type: ignore[no-untyped-def]
    c: TaskCounters = runner.counters
    n = c.picks_completed + c.picks_failed
    t = Table.grid(padding=(0, 2))
    t.add_row(
        "task",
        f"[bold]{runner.task}[/bold]",
        "state",
        f"[cyan]{runner.state.value}[/cyan] {runner.message[:48]}",
    )
    t.add_row(
        "cycles", str(n), "success", f"{c.picks_completed}/{n} ({100 * c.success_rate:.0f} %)" if n else "-"
    )
    t.add_row(
        "avg cycle",
        f"{c.average_cycle_time:.1f} s" if c.cycle_times_s else "-",
        "running for",
        f"{time.perf_counter() - started:.0f} s",
    )
    lines: list[Table | Text] = [t]
    if last is not None:
        colour = "green" if last.success else "red"
        lines.append(
            Text.from_markup(
                f"last: [{colour}]{'success' if last.success else 'failed'}[/{colour}] in {last.cycle_time_s:.1f} s"
                + ("" if last.success else f" — {last.stage_reached}: {last.failure_reason[:90]}")
            )
        )
    return Group(*lines)


@contextlib.asynccontextmanager
async def aio_session(cm: contextlib.AbstractContextManager[object]) -> AsyncIterator[object]:
    with cm as value:
        yield value


def cell_keeps_running(cycles: int, task_running: bool, cycles_done: int) -> bool:
    """Whether ``pickplace up`` stays up. It lives until Ctrl-C or SIGTERM: a Stop, an e-stop from any
    source or a failed task leave every service up (so Reset and Start, or a calibration, can follow).
    Only a run asked for ``cycles`` (> 0) ends by itself, once the task has finished that many."""
    return cycles <= 0 or task_running or cycles_done < cycles


async def run_pick_cell(
    settings: Settings,
    cycles: int,
    console: Console,
    on_ready: Callable[[Cell, str], None] | None = None,
    on_tick: Callable[[], None] | None = None,
) -> TaskCounters:
    """``on_ready(cell, dashboard_url)`` once everything serves; ``on_tick()`` after each display refresh."""
    started = time.perf_counter()
    last: list[PickOutcome] = []
    from gateway.server import embedded_gateway, embedded_settings
    from services.apps.launcher import session_log, with_state_dir

    # the cell's token before its services are built: every gRPC service asks for it (as the edge does)
    settings, _token = embedded_settings(with_state_dir(settings))
    async with (
        aio_session(session_log(settings, "up")),
        Cell(settings, engine="twin") as cell,
        embedded_gateway(
            cell.settings,
            cell.bus,
            calibration_executor=_calibration_executor(cell),
            metrics_registries=_service_registries(cell),
        ) as (_gw, url),
        cell_live_view(cell, console),  # Foxglove live view and --record (record.*)
    ):
        runner = cell.task.runner  # type: ignore[union-attr]
        runner.listeners.append(last.append)
        s = cell.settings
        console.print(f"dashboard: [link={url}]{url}[/link]")
        console.print(
            f"[bold]pickplace[/bold] cell [cyan]{s.cell_id}[/cyan]: simulated {s.robot.model} twin on "
            f"{cell.sim_address} (seed {cell.seed}), {s.robot.driver.value} driver, gRPC robot {s.grpc.robot_port} / "
            f"task {s.grpc.task_port}, Zenoh {s.zenoh.listen}; calibration: {cell.vision.calibration_source}"  # type: ignore[union-attr]
        )
        console.print("Ctrl-C stops after a summary. Another terminal: [green]pickplace robot watch[/green]")
        _tap_camera(cell, _gw.app.state.cell.hub.on_sensor_frame)
        runner.start(cycles=cycles)
        if on_ready is not None:
            on_ready(cell, url)
        try:
            with Live(_status_table(runner, started, None), console=console, refresh_per_second=4) as live:
                while cell_keeps_running(cycles, runner.running, len(runner.outcomes)):
                    await asyncio.sleep(0.25)  # the display's refresh, not a wait for the arm
                    live.update(_status_table(runner, started, last[-1] if last else None))
                    if on_tick is not None:
                        on_tick()
                live.update(_status_table(runner, started, last[-1] if last else None))
        finally:
            with contextlib.suppress(Exception):
                await runner.stop()
            _pick_summary(console, runner.counters, runner.outcomes)
        return runner.counters


class _FrameTap:
    """The vision service's camera, handing every frame it captures to the dashboard too (its colour
    and depth views), so the embedded cell needs no frame stream on the bus."""

    def __init__(self, camera: Camera, on_frame: Callable[[RGBDFrame], None]):
        self._camera = camera
        self._on_frame = on_frame

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._camera.intrinsics

    def capture(self) -> RGBDFrame:
        frame = self._camera.capture()
        self._on_frame(frame)
        return frame

    def close(self) -> None:
        self._camera.close()


def _tap_camera(cell: Cell, on_frame: Callable[[RGBDFrame], None]) -> None:
    if cell.vision is not None and cell.vision.camera is not None:
        cell.vision.camera = _FrameTap(cell.vision.camera, on_frame)


def _service_registries(cell: Cell) -> list[object]:
    """The other services' metric registries, exported at the gateway's /metrics (vision's latency)."""
    return [cell.vision.metrics.registry] if cell.vision is not None else []


def _calibration_executor(cell: Cell):  # type: ignore[no-untyped-def]
    """POST /calibration/handshake in the embedded cell: the eye-to-hand routine with the board held by
    the gripper (in the twin: ``sim.twin.calibration_board: true``), on the cell's own camera and robot.
    The result is stored by the gateway; the calibration file is written only by `pickplace calibrate`."""
    from gateway.calibration import CalibrationOutcome
    from services.apps.calibration_cli import GrpcCalibrationRobot
    from services.common.errors import InvalidInputError
    from services.vision.calibrate_workflow import run_calibration

    async def execute(num_poses: int, progress) -> CalibrationOutcome:  # type: ignore[no-untyped-def]
        runner = cell.task.runner  # type: ignore[union-attr]
        if runner.running:
            raise InvalidInputError("stop the task before calibrating: the arm is busy")
        s = cell.settings
        cal = s.vision.calibration.model_copy(update={"n_poses": num_poses})
        vision = cell.vision
        if vision is None or vision.camera is None:
            raise InvalidInputError("calibration needs the cell's vision service and its camera")
        guess = vision.T_base_camera
        if guess is None:
            raise InvalidInputError(
                "calibration needs a rough camera pose: write one with `pickplace calibrate-manual`"
            )
        async with GrpcCalibrationRobot(s, speed_ratio=30) as robot:
            result, _data = await run_calibration(
                robot,
                vision.camera,
                cal,
                guess,
                progress=lambda done, total, msg: progress(done / max(total, 1), msg),
            )
        return CalibrationOutcome(
            parameters={
                "T_base_camera": result.T_base_camera.tolist(),
                "poses_used": result.n_poses,
                "method": result.method,
                "translation_rms_m": result.translation_rms_m,
                "rotation_rms_deg": result.rotation_rms_deg,
            },
            reprojection_error=result.reprojection_rms_px,
            notes="eye-to-hand, ChArUco board held by the gripper",
        )

    return execute


def _pick_summary(console: Console, c: TaskCounters, outcomes: list[PickOutcome]) -> None:
    n = c.picks_completed + c.picks_failed
    t = Table(title="summary")
    t.add_column("metric")
    t.add_column("value", justify="right")
    t.add_row("cycles", str(n))
    t.add_row("successful picks", f"{c.picks_completed} ({100 * c.success_rate:.0f} %)" if n else "0")
    if c.cycle_times_s:
        t.add_row("mean cycle time", f"{c.average_cycle_time:.2f} s")
    failures: dict[str, int] = {}
    for o in outcomes:
        if not o.success:
            key = f"{o.stage_reached}: {o.error_code or 'failed'}"
            failures[key] = failures.get(key, 0) + 1
    for key, count in sorted(failures.items(), key=lambda kv: -kv[1]):
        t.add_row(f"failed at {key}", str(count))
    console.print(t)


# ---------------------------------------------------------------------------- key-pose demo
def ur_keypose_settings(settings: Settings) -> Settings:
    """A UR's key-pose job: the UR cell's settings (driver ur_rtde, gripper on the tool outputs) and,
    unless a cycle is configured, seed 003's own (``SEED_003_CYCLE``: its poses, dwell and the tool
    tip's box they need)."""
    from services.sim.twin.ur_cell import ur_cell_settings

    s = ur_cell_settings(settings, settings.robot.model)
    if s.cycle == KeyPoseCycleSettings():
        seed_003 = load_settings(settings.profile, SEED_003_CYCLE)
        robot = s.robot.model_copy(update={"workspace": seed_003.robot.workspace})
        s = s.model_copy(update={"cycle": seed_003.cycle, "robot": robot})
    return s


@contextlib.asynccontextmanager
async def keypose_sim(settings: Settings, engine: str) -> AsyncIterator[Settings]:
    """The simulated controller of ``settings.robot.model`` for the key-pose job; yields the settings
    that reach it (a UR: its own process on a loopback address of its own; a Nova5: in this process)."""
    if is_ur(settings):
        from services.sim.ur.process import SimSpec, URSimProcess
        from services.sim.ur.server import free_loopback_host

        host = await asyncio.to_thread(free_loopback_host)
        spec = SimSpec(settings.robot.model, host, twin=engine == "twin", settings=settings)
        sim = URSimProcess(spec)
        await asyncio.to_thread(sim.__enter__)
        try:
            yield settings.model_copy(update={"robot": settings.robot.model_copy(update={"host": host})})
        finally:
            await asyncio.to_thread(sim.__exit__, None, None, None)
        return
    async with build_sim_server(settings, engine) as server:
        r = settings.robot.model_copy(
            update={"dashboard_port": server.ports["dashboard"], "feedback_port": server.ports["feedback"]}
        )
        yield settings.model_copy(update={"robot": r})


async def run_keypose_demo(settings: Settings, cycles: int, engine: str, console: Console) -> CycleReport:
    total = CycleReport()
    if is_ur(settings):
        settings = ur_keypose_settings(settings)
    async with (
        keypose_sim(settings, engine) as settings,  # rebound: the settings that reach the sim
        Bus(settings.zenoh) as bus,
        RobotService(settings, bus) as svc,
    ):
        console.print(
            f"key-pose cycle on the simulated {settings.robot.model} ({engine}, "
            f"{settings.robot.driver.value} driver on {settings.robot.host}); gRPC "
            f"{settings.grpc.host}:{svc.grpc_port}, Zenoh {settings.zenoh.listen}"
        )
        await svc.driver.enable()

        def show(ev: CycleEvent) -> None:
            console.print(
                f"cycle {ev.cycle} [{ev.step}/{ev.steps}] → [bold]{ev.pose:<10}[/bold] "
                f"in {ev.duration_s:5.2f}s (error {ev.position_error_deg:.3f}°)"
            )

        try:
            for _ in itertools.islice(itertools.count(), cycles):
                # svc.settings follows PUT /config: a changed cycle or speed applies from the next cycle
                rep = await run_keypose_cycle(
                    svc.driver, svc.settings.cycle, 1, svc.settings.robot.speed_ratio, show
                )
                total.cycles += rep.cycles
                total.moves += rep.moves
                total.cycle_times_s += rep.cycle_times_s
                total.max_position_error_deg = max(total.max_position_error_deg, rep.max_position_error_deg)
        finally:
            t = Table(title="summary")
            t.add_column("metric")
            t.add_column("value", justify="right")
            t.add_row("cycles", str(total.cycles))
            t.add_row("moves", str(total.moves))
            t.add_row("max end-of-move error", f"{total.max_position_error_deg:.3f}°")
            t.add_row("joint states published", str(svc.hub.published))
            console.print(t)
    return total
