"""Typer commands of the twin, for the lead's ``pickplace`` app to mount.

``app.registered_commands`` holds ``sim-scene`` (write a seeded RGB-D frame set + ground truth)
and ``sim-mjcf`` (write the cell's MJCF, e.g. to open it in MuJoCo's viewer). Mount with
``main_app.add_typer(twin_cli.app)`` (commands appear at top level: ``pickplace sim-scene``) or
register the functions one by one.
"""

from __future__ import annotations

from pathlib import Path

import typer

from services.common.errors import RobotError
from services.common.settings import load_settings

app = typer.Typer(help="Physics twin of the cell: scenes, frame sets, MJCF.", no_args_is_help=True)


@app.command("sim-scene")
def sim_scene(
    out: Path = typer.Option(..., "--out", help="directory for the frame set"),
    seed: int = typer.Option(0, "--seed", min=0, help="scene seed (rod pose, cube layout, noise)"),
    frames: int = typer.Option(1, "--frames", min=1, max=1000),
    noise: bool = typer.Option(True, "--noise/--no-noise", help="D435i depth/RGB noise model"),
    profile: str | None = typer.Option(None, "--profile", help="config profile (default: sim)"),
) -> None:
    """Write an RGB-D frame set + intrinsics + ground truth of a seeded twin scene."""
    from services.sim.twin.dataset import write_sim_scene

    try:
        path = write_sim_scene(seed, out, load_settings(profile=profile), frames=frames, noise=noise)
    except RobotError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from exc
    typer.echo(f"wrote {frames} frame(s) and {path}")


@app.command("sim-mjcf")
def sim_mjcf(
    out: Path = typer.Option(..., "--out", help="MJCF file to write"),
    seed: int = typer.Option(0, "--seed", min=0),
    profile: str | None = typer.Option(None, "--profile"),
) -> None:
    """Write the twin's MJCF (robot, gripper, table, seeded objects, camera)."""
    from services.sim.twin.model import build_world

    try:
        world = build_world(load_settings(profile=profile), seed)
    except RobotError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from exc
    out.write_text(world.xml)
    typer.echo(f"wrote {out}")
