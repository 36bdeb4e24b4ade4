"""The ``pickplace`` command line (typer)."""

from __future__ import annotations

import asyncio
import json
import logging
import sys
from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from gateway.cli import db_app
from services.apps.calibration_cli import app as calibration_app
from services.apps.record_cli import app as record_app
from services.apps.record_cli import record_overrides
from services.apps.ur_cli import app as ur_app
from services.apps.vision_cli import app as vision_app
from services.common.aio import run_until_signal
from services.common.bus import Bus
from services.common.errors import ConfigurationError, RobotError
from services.common.logs import setup_logging
from services.common.modes import GripperCommand, TaskKind
from services.common.net import free_loopback_port
from services.common.priority import favour_process, process_nice
from services.common.settings import Settings, load_settings
from services.sim.twin.cli import app as twin_app

if TYPE_CHECKING:
    import grpc.aio
    from pickplace.v1.robot_pb2_grpc import RobotControllerStub

app = typer.Typer(
    help="pickplace: vision-guided pick-and-place cell controller",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
)
robot_app = typer.Typer(
    help="operate the robot through the robot-driver service (gRPC)", no_args_is_help=True
)
app.add_typer(robot_app, name="robot")
app.add_typer(db_app, name="db")  # the gateway's `pickplace db upgrade|downgrade|current`
app.add_typer(twin_app)  # sim-scene, sim-mjcf
app.add_typer(vision_app)  # vision-detect, record
app.add_typer(calibration_app)  # calibrate, calibrate-manual, calibration-check
app.add_typer(record_app)  # replay
app.add_typer(ur_app)  # sim-ur
console = Console()
log = logging.getLogger("pickplace.cli")

ProfileOpt = Annotated[str | None, typer.Option("--profile", "-p", help="config profile (sim, nova5-real)")]
ConfigOpt = Annotated[str | None, typer.Option("--config", "-c", help="extra YAML config file")]
FoxglovePortOpt = Annotated[
    int | None, typer.Option("--foxglove-port", help="Foxglove live view port (8765)")
]
NoFoxgloveOpt = Annotated[bool, typer.Option("--no-foxglove", help="no Foxglove live view")]
RecordOpt = Annotated[str | None, typer.Option("--record", help="record MCAP files under this directory")]


def _settings(
    profile: str | None, config: str | None, console_log: bool = True, **overrides: Any
) -> Settings:
    try:
        s = load_settings(profile, config, overrides={k: v for k, v in overrides.items() if v})
    except ConfigurationError as exc:
        console.print(f"[red]configuration error:[/red] {exc}", soft_wrap=True)
        raise typer.Exit(2) from None
    setup_logging(s.logging, console=console_log)
    return s


def _run(coro: Coroutine[Any, Any, Any]) -> Any:
    """Run a coroutine; Ctrl-C cancels it cleanly; pickplace errors exit 1 with their message."""

    try:
        return run_until_signal(coro)
    except asyncio.CancelledError:
        console.print("[yellow]stopped[/yellow]")
        return None
    except RobotError as exc:
        console.print(f"[red]{type(exc).__name__}:[/red] {exc}", soft_wrap=True)
        raise typer.Exit(1) from None
    except OSError as exc:  # typically a port another pickplace process already holds
        console.print(f"[red]cannot start:[/red] {exc} (is another pickplace cell running?)", soft_wrap=True)
        raise typer.Exit(1) from None


# ---------------------------------------------------------------------------- up / run
@app.command()
def up(
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
    cycles: Annotated[int, typer.Option(help="pick cycles to run (0 = until Ctrl-C)")] = 0,
    task: Annotated[str, typer.Option(help="stand-rod | sort-cubes")] = "",
    seed: Annotated[int | None, typer.Option(help="first twin scene seed")] = None,
    job: Annotated[str, typer.Option(help="pick (the cell) | keypose (seed 003's demo cycle)")] = "pick",
    processes: Annotated[
        bool, typer.Option("--processes", help="every service as its own OS process")
    ] = False,
    foxglove_port: FoxglovePortOpt = None,
    no_foxglove: NoFoxgloveOpt = False,
    record: RecordOpt = None,
) -> None:
    """Run the whole cell: in one process (default) or as separate processes on loopback."""
    from services.apps.up import run_all_in_one

    overrides: dict[str, Any] = {"record": record_overrides(foxglove_port, no_foxglove, record)}
    if task:
        overrides["task"] = {"task": task}
    if seed is not None:
        overrides["sim"] = {"seed": seed}
    s = _settings(profile, config, console_log=False, **overrides)
    # before any thread or service process starts: they inherit it
    favour_process(s.robot.process_nice, "the cell")
    if processes:
        from services.apps.launcher import run_processes

        _run(run_processes(s, cycles=cycles, console=console))
        return
    _run(run_all_in_one(s, cycles=cycles, console=console, job=job))


@app.command("eval")
def evaluate(
    trials: Annotated[int, typer.Option(min=1, help="number of seeded trials")] = 20,
    seed: Annotated[int, typer.Option(min=0, help="seed of the first scene")] = 0,
    task: Annotated[str, typer.Option(help="stand-rod | sort-cubes")] = TaskKind.STAND_ROD,
    speed: Annotated[float, typer.Option(help="sim time per wall time")] = 3.0,
    calibration_error_mm: Annotated[float, typer.Option(help="inject this camera position error")] = 0.0,
    calibration_error_deg: Annotated[float, typer.Option(help="inject this camera rotation error")] = 0.0,
    json_out: Annotated[
        str,
        typer.Option(
            "--json",
            help="write the full report as JSON here; each trial is also journalled as it ends, in "
            "<this path>.trials.jsonl",
        ),
    ] = "",
    resume: Annotated[
        bool,
        typer.Option("--resume", help="continue an interrupted run: take the trials its journal holds"),
    ] = False,
    load: Annotated[
        int, typer.Option(min=0, help="run N busy processes beside the cell (outcomes must not change)")
    ] = 0,
    nominal: Annotated[
        bool,
        typer.Option("--nominal", help="no per-trial randomization: every trial in the configured world"),
    ] = False,
    robot: Annotated[
        str, typer.Option(help="robot model: nova5 | ur5e | ur3 (a UR runs on the simulated UR, ur_rtde)")
    ] = "",
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Run N seeded pick trials in the twin, each in its own randomized world (sim.twin.randomization),
    and report success with its 95 % interval, cycle time, failures and success per parameter bin."""
    from pathlib import Path

    from services.apps.eval_journal import TrialJournal, journal_path
    from services.apps.evaluation import print_report, run_eval, write_report

    if task not in tuple(TaskKind):
        console.print(f"[red]--task must be stand-rod or sort-cubes, not {task!r}[/red]")
        raise typer.Exit(2)
    if resume and not json_out:
        console.print("[red]--resume needs --json: the journal it continues lies beside that report[/red]")
        raise typer.Exit(2)
    # a self-contained run: free loopback ports, so it never collides with a running cell
    zport = free_loopback_port()
    s = _settings(
        profile,
        config,
        console_log=False,
        sim={"speed": speed, "dashboard_port": 0, "feedback_port": 0, "slow_feedback_port": 0},
        grpc={"robot_port": 0, "motion_port": 0, "grasp_port": 0, "vision_port": 0, "task_port": 0},
        zenoh={"listen": [f"tcp/127.0.0.1:{zport}"]},
        **({"robot": {"model": robot}} if robot else {}),
    )
    s.logging.level = "WARNING"
    setup_logging(s.logging, console=True)
    # the cell before other work, as `pickplace up` runs it; the load stays at the nice this run had
    ordinary_nice = process_nice()
    favour_process(s.robot.process_nice, "the cell")
    error = None
    if calibration_error_mm or calibration_error_deg:
        error = (calibration_error_mm / 1000.0, calibration_error_deg)
    journal = None
    if json_out:
        header = {
            "task": task,
            "seed": seed,
            "trials": trials,
            "randomized": not nominal,
            "calibration_error": list(error) if error else None,
            "robot": s.robot.model,
            "speed": speed,
            "load": load,
        }
        try:
            journal = TrialJournal.open(journal_path(Path(json_out)), header, resume)
        except ConfigurationError as exc:
            console.print(f"[red]{exc}[/red]")
            raise typer.Exit(2) from exc
        if journal.done:
            console.print(f"resuming: {len(journal.done)} trials taken from {journal.path}")
    try:
        report = _run(
            run_eval(
                s,
                trials,
                seed,
                task,
                error,
                console,
                load=load,
                randomize=not nominal,
                journal=journal,
                load_nice=ordinary_nice,
            )
        )
    finally:
        if journal is not None:
            journal.close()
    if report is None:
        return
    print_report(report, console)
    if json_out:
        write_report(report, Path(json_out))
        console.print(f"JSON report written to {json_out}")
    else:
        console.print_json(json.dumps(report.summary()))


# ---------------------------------------------------------------------------- sim
@app.command("sim-dobot")
def sim_dobot(
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
    engine: Annotated[str, typer.Option(help="motion engine: kinematic | twin")] = "",
    seed: Annotated[int | None, typer.Option(help="scene seed (twin)")] = None,
    speed: Annotated[float | None, typer.Option(help="sim time per wall time; 0 = as possible")] = None,
    dashboard_port: Annotated[int | None, typer.Option()] = None,
    feedback_port: Annotated[int | None, typer.Option()] = None,
    frames: Annotated[
        bool | None,
        typer.Option(
            "--frames/--no-frames", help="publish the twin camera on Zenoh (default: on with the twin)"
        ),
    ] = None,
    frame_rate: Annotated[
        float, typer.Option(help="camera frames per second on Zenoh (0 = vision.rate_hz)")
    ] = 0.0,
) -> None:
    """Run a simulated Nova5 controller on 127.0.0.1 (ports 29999/30004/30005 by default).

    With the twin engine it also joins Zenoh: camera frames out, scene resets in (services.sim.bus_link).
    """
    from services.sim.app import build_sim_server

    sim: dict[str, Any] = {}
    if engine:
        sim["engine"] = engine
    if seed is not None:
        sim["seed"] = seed
    if speed is not None:
        sim["speed"] = speed if speed > 0 else 1e9
    if dashboard_port is not None:
        sim["dashboard_port"] = dashboard_port
    if feedback_port is not None:
        sim["feedback_port"] = feedback_port
    s = _settings(profile, config, sim=sim)
    from services.apps.probes import start_metrics_exporter

    start_metrics_exporter(s)  # off unless metrics.port is set (compose / Kubernetes), as in `serve`

    async def main() -> None:
        async with build_sim_server(s) as server:
            console.print(
                f"simulated {s.robot.model} ({s.sim.engine} engine) on {s.sim.host}: {server.ports}"
            )
            if s.sim.engine != "twin":
                await asyncio.Event().wait()
            from services.common.bus import Bus
            from services.sim.bus_link import SimBusLink

            rate = frame_rate if frame_rate > 0 else s.vision.rate_hz
            async with (
                Bus(s.zenoh) as bus,
                SimBusLink(s, server, bus, frames=frames is not False, frame_rate=rate),
            ):
                await asyncio.Event().wait()

    _run(main())


# ---------------------------------------------------------------------------- serve
SERVICES = ("robot", "motion", "grasp", "vision", "task", "gateway", "record")


@app.command()
def serve(
    service: Annotated[str, typer.Argument(help="service to run: " + " | ".join(SERVICES))],
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
    foxglove_port: FoxglovePortOpt = None,
    no_foxglove: NoFoxgloveOpt = False,
    record: RecordOpt = None,
) -> None:
    """Run one service in this process (what docker-compose and Kubernetes run)."""
    if service not in SERVICES:
        console.print(f"[red]unknown service {service!r}[/red]; available: {', '.join(SERVICES)}")
        raise typer.Exit(2)
    s = _settings(profile, config, record=record_overrides(foxglove_port, no_foxglove, record))
    from services.apps.probes import start_metrics_exporter

    start_metrics_exporter(s)  # off unless metrics.port is set (compose / Kubernetes)
    if service == "robot":
        from services.robot.service import serve as run
    elif service == "motion":
        from services.motion.service import serve as run
    elif service == "grasp":
        from services.grasp.service import serve as run
    elif service == "vision":
        from services.vision.service import serve as run
    elif service == "task":
        from services.task.service import serve as serve_task

        _run(serve_task(s, between_cycles=_scene_reset_between_cycles(s)))
        return
    elif service == "record":  # the live view and recorder of the cell (--foxglove-port, --record)
        from services.apps.record_cli import serve_record as run
    else:
        from gateway.server import serve as run
    _run(run(s))


def _scene_reset_between_cycles(s: Settings) -> Callable[[Bus], object] | None:
    """In the simulated cell, the simulated operator lays out a fresh scene (in sim-dobot) between cycles."""
    if not (s.task.reset_scene_each_cycle and s.profile == "sim"):
        return None
    from services.sim.bus_link import request_scene_reset

    return lambda bus: request_scene_reset(bus, s.cell_id)


# ---------------------------------------------------------------------------- robot operator CLI
def _robot_stub(s: Settings) -> tuple[grpc.aio.Channel, RobotControllerStub]:
    from pickplace.v1 import robot_pb2_grpc

    from services.common.grpc_util import cell_token, channel

    ch = channel(s.grpc.client_host("robot"), s.grpc.robot_port, cell_token(s))
    return ch, robot_pb2_grpc.RobotControllerStub(ch)


async def _robot_call(s: Settings, method: str, request: Any) -> Any:
    from services.common.grpc_util import rpc_errors

    ch, stub = _robot_stub(s)
    async with ch:
        with rpc_errors():
            return await getattr(stub, method)(request, timeout=s.grpc.request_timeout_s * 10)


@robot_app.command("status")
def robot_status(profile: ProfileOpt = None, config: ConfigOpt = None) -> None:
    """Robot mode, alarms, joints and tool pose."""
    from pickplace.v1 import robot_pb2

    s = _settings(profile, config, console_log=False)
    st = _run(_robot_call(s, "GetStatus", robot_pb2.GetStatusRequest()))
    t = Table(title=f"{st.robot_model} — {st.robot_mode_name} ({st.robot_mode})")
    t.add_column("joint")
    t.add_column("deg", justify="right")
    for n, p in zip(st.joint_state.name, st.joint_state.position, strict=False):
        t.add_row(n, f"{np.rad2deg(p):9.3f}")
    console.print(t)
    pose = st.joint_state.tcp_pose
    console.print(
        f"tool at ({pose.x:.4f}, {pose.y:.4f}, {pose.z:.4f}) m; enabled={st.enabled} "
        f"e-stop={st.estop_active} gripper={'closed' if st.gripper_closed else 'open'} "
        f"alarms={list(st.alarms)}"
    )


def _simple(method: str, request_factory: str, **kw: Any) -> Callable[[ProfileOpt, ConfigOpt], None]:
    def cmd(profile: ProfileOpt = None, config: ConfigOpt = None) -> None:
        from pickplace.v1 import robot_pb2

        s = _settings(profile, config, console_log=False)
        r = _run(_robot_call(s, method, getattr(robot_pb2, request_factory)(**kw)))
        console.print(r.message)

    return cmd


robot_app.command("enable", help="enable the arm")(_simple("Enable", "EnableRequest"))
robot_app.command("disable", help="disable the arm")(_simple("Disable", "DisableRequest"))
robot_app.command("clear", help="clear controller alarms")(_simple("ClearError", "ClearErrorRequest"))
robot_app.command("stop", help="stop motion")(_simple("Stop", "StopRequest"))
robot_app.command("estop", help="press the software emergency stop")(
    _simple("EmergencyStop", "EmergencyStopRequest")
)
robot_app.command("estop-release", help="release the software emergency stop")(
    _simple("EmergencyStop", "EmergencyStopRequest", release=True)
)


@robot_app.command("move-joints")
def robot_move_joints(
    joints_deg: Annotated[list[float], typer.Argument(help="six joint angles in degrees")],
    speed: Annotated[int, typer.Option(help="speed ratio 1-100 %")] = 30,
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Move to a joint configuration (checked against limits and workspace first)."""
    from pickplace.v1 import robot_pb2

    s = _settings(profile, config, console_log=False)
    req = robot_pb2.MoveJointsRequest(positions=np.deg2rad(joints_deg).tolist(), speed_ratio=speed)
    r = _run(_robot_call(s, "MoveJoints", req))
    console.print(
        f"{r.message} in {r.execution_time:.2f}s: {np.round(np.rad2deg(r.final_positions), 3).tolist()}"
    )


@robot_app.command("gripper")
def robot_gripper(
    action: Annotated[str, typer.Argument(help="open | close")],
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Open or close the gripper."""
    from pickplace.v1 import robot_pb2

    if action not in tuple(GripperCommand):
        console.print(f"[red]gripper action must be open or close, not {action!r}[/red]")
        raise typer.Exit(2)
    s = _settings(profile, config, console_log=False)
    r = _run(_robot_call(s, "SetGripper", robot_pb2.SetGripperRequest(close=action == GripperCommand.CLOSE)))
    console.print(r.message)


@robot_app.command("watch")
def robot_watch(
    via: Annotated[str, typer.Option(help="grpc | zenoh")] = "grpc",
    rate: Annotated[float, typer.Option(help="max messages per second to print")] = 5.0,
    count: Annotated[int, typer.Option(help="stop after N printed messages (0 = until Ctrl-C)")] = 0,
    profile: ProfileOpt = None,
    config: ConfigOpt = None,
) -> None:
    """Watch joint states stream (gRPC StreamJointStates, or the Zenoh topic)."""
    s = _settings(profile, config, console_log=False)
    _run(watch_joint_states(s, via, rate, count))


async def watch_joint_states(s: Settings, via: str, rate: float, count: int) -> int:
    from pickplace.v1 import common_pb2, robot_pb2

    printed = 0
    interval_ns = int(1e9 / rate) if rate > 0 else 0
    last = 0

    def show(msg: common_pb2.JointState) -> bool:
        nonlocal printed, last
        if msg.header.stamp_ns - last < interval_ns:
            return False
        last = msg.header.stamp_ns
        printed += 1
        q = np.round(np.rad2deg(msg.position), 2).tolist()
        console.print(f"#{msg.header.seq:7d} mode={msg.robot_mode:2d} q[deg]={q}")
        return bool(count) and printed >= count

    if via == "grpc":
        from services.common.grpc_util import rpc_errors

        ch, stub = _robot_stub(s)
        async with ch:
            with rpc_errors():
                async for msg in stub.StreamJointStates(robot_pb2.StreamJointStatesRequest()):
                    if show(msg):
                        break
    elif via == "zenoh":
        from services.common.bus import Bus
        from services.common.keys import CellKeys

        # connect to the running cell's endpoint instead of listening on it
        zs = s.zenoh.model_copy(
            update={"listen": [], "connect": list(s.zenoh.listen) + list(s.zenoh.connect)}
        )
        async with Bus(zs) as bus:
            sub = bus.subscribe(CellKeys(s.cell_id).joint_states, common_pb2.JointState)
            try:
                async for msg in sub:
                    if show(msg):
                        break
            finally:
                sub.close()
    else:
        console.print(f"[red]--via must be grpc or zenoh, not {via!r}[/red]")
        raise typer.Exit(2)
    return printed


def main() -> None:
    try:
        app()
    except KeyboardInterrupt:
        sys.exit(130)


if __name__ == "__main__":
    main()
