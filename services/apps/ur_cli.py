"""``pickplace sim-ur``: a simulated Universal Robots e-Series controller on a loopback address.

RTDE on 30004, the dashboard on 29999 and the script ports 30001-30003 (ur_rtde fixes them; a second
simulated controller takes another loopback address, e.g. ``--host 127.0.0.2``). See docs/ur/rtde.md.
"""

from __future__ import annotations

import asyncio
import enum
import logging
from typing import TYPE_CHECKING, Annotated

import typer

from services.common.aio import run_until_signal
from services.common.logs import setup_logging
from services.common.settings import Settings, load_settings
from services.common.settings.robot import RobotDriverKind

if TYPE_CHECKING:
    from services.robot.demo_cycle import CycleReport

app = typer.Typer(help="Simulated Universal Robots controller.", no_args_is_help=True)
log = logging.getLogger("pickplace.sim.ur")


class URModel(enum.StrEnum):
    UR5E = "ur5e"
    UR3 = "ur3"


class Engine(enum.StrEnum):
    KINEMATIC = "kinematic"  # the reference followed exactly
    TWIN = "twin"  # the MuJoCo cell: scene, camera, gripper on the tool outputs


@app.command("sim-ur")
def sim_ur(
    model: Annotated[URModel | None, typer.Option(help="arm model (default: robot.model when a UR)")] = None,
    host: Annotated[
        str | None, typer.Option(help="loopback address to listen on (default robot.host)")
    ] = None,
    speed: Annotated[float, typer.Option(min=0.01, max=100, help="controller time per wall time")] = 1.0,
    powered: Annotated[
        bool, typer.Option("--powered/--powered-off", help="boot with brakes released")
    ] = False,
    unlock_delay_s: Annotated[float, typer.Option(min=0, help="protective stop unlock delay")] = 5.0,
    rtde_port: Annotated[int, typer.Option(min=1, max=65535)] = 30004,
    dashboard_port: Annotated[int, typer.Option(min=1, max=65535)] = 29999,
    engine: Annotated[Engine, typer.Option(help="motion engine behind the controller")] = Engine.KINEMATIC,
    seed: Annotated[int | None, typer.Option(help="twin scene seed (default sim.seed)")] = None,
    profile: Annotated[str | None, typer.Option("--profile", "-p", help="config profile")] = None,
) -> None:
    """Run a simulated UR5e/UR3 controller that ur_rtde drives like a real one, until Ctrl-C."""
    from services.kinematics.robot_models import get_robot
    from services.sim.ur.controller import URController, URControllerConfig
    from services.sim.ur.server import URPorts, URSimServer, check_loopback

    settings = load_settings(profile)
    setup_logging(settings.logging)
    name = (
        model.value
        if model
        else (settings.robot.model if settings.robot.model in ("ur5e", "ur3") else "ur5e")
    )
    address = host or settings.robot.host
    try:
        check_loopback(address)
    except ValueError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from exc
    twin = None
    q0 = URControllerConfig().q0
    if engine is Engine.TWIN:
        import numpy as np

        from services.sim.twin.ur_cell import create_ur_twin_engine

        twin = create_ur_twin_engine(settings, name, seed)
        q0 = tuple(float(v) for v in np.deg2rad(settings.sim.twin.initial_joints_deg))
    config = URControllerConfig(start_powered=powered, unlock_delay_s=unlock_delay_s, q0=q0)
    controller = URController(get_robot(name), config, twin)

    async def main() -> None:
        async with URSimServer(controller, address, URPorts(rtde_port, dashboard_port), speed):
            typer.echo(
                f"simulated {name} on {address}: RTDE {rtde_port}, dashboard {dashboard_port}, script 30001-30003"
            )
            await asyncio.Event().wait()

    try:
        run_until_signal(main())
    except asyncio.CancelledError:
        pass
    except OSError as exc:
        typer.echo(f"error: cannot listen on {address}: {exc}", err=True)
        raise typer.Exit(1) from exc


async def run_ur_keypose(settings: Settings, cycles: int, twin: bool) -> CycleReport:
    """Seed 003's key-pose cycle on a simulated UR (its own process) through the shared driver."""
    from services.robot.demo_cycle import run_keypose_cycle
    from services.robot.service import build_driver
    from services.sim.ur.process import SimSpec, URSimProcess
    from services.sim.ur.server import free_loopback_host

    spec = SimSpec(settings.robot.model, free_loopback_host(), twin=twin, seed=settings.sim.seed)
    with URSimProcess(spec) as sim:
        robot = settings.robot.model_copy(update={"host": sim.host})
        driver = build_driver(settings.model_copy(update={"robot": robot}))
        try:
            await driver.start()
            await driver.enable()
            return await run_keypose_cycle(driver, settings.cycle, cycles, settings.robot.speed_ratio)
        finally:
            await driver.client.close()


@app.command("ur-keypose")
def ur_keypose(
    cycles: Annotated[int, typer.Option(min=1, max=1000)] = 1,
    engine: Annotated[Engine, typer.Option(help="motion engine behind the controller")] = Engine.KINEMATIC,
    profile: Annotated[str | None, typer.Option("--profile", "-p", help="config profile")] = None,
    config: Annotated[
        str | None, typer.Option("--config", "-c", help="extra YAML (config/robots/ur3-keypose.yaml)")
    ] = None,
) -> None:
    """Run seed 003's key-pose cycle on a simulated UR through ur_rtde and the shared RobotDriver."""
    settings = load_settings(profile, config)
    if settings.robot.driver is not RobotDriverKind.UR_RTDE:
        typer.echo("error: robot.driver must be ur_rtde (e.g. -c config/robots/ur3-keypose.yaml)", err=True)
        raise typer.Exit(2)
    setup_logging(settings.logging)
    report = asyncio.run(run_ur_keypose(settings, cycles, engine is Engine.TWIN))
    times = ", ".join(f"{t:.2f}" for t in report.cycle_times_s)
    typer.echo(
        f"{settings.robot.model}: {report.cycles} cycle(s), {report.moves} moves, cycle times {times} s, "
        f"largest final position error {report.max_position_error_deg:.4f}°"
    )


if __name__ == "__main__":  # ``python -m services.apps.ur_cli sim-ur …``: without the whole CLI
    app()
