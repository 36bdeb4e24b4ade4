"""Recording benchmark (issue 17): CPU and bytes per minute of recorded cell data, and cycle times with and without.

1. One minute of cell data, as the cell produces it — joint states at 125 Hz (the controller's feedback),
   camera frames and detections at the vision rate (5 Hz, frames from the seeded synthetic D435i renderer,
   noise included), task status at 2 Hz, a log line a second — is fed to the recorder as fast as it takes
   it. Reported: the process CPU time it took per minute of data (= the share of one core recording costs
   in a running cell) and the bytes of MCAP per minute, with the live view off and on (no client).
2. ``pickplace up``-like twin cycles with and without recording (``N_CYCLES`` each, seeded scenes):
   the mean cycle time on the controller's clock and on the wall clock.

Run: ``python -m bench.bench_record`` (or ``python -m bench record``).
"""

from __future__ import annotations

import asyncio
import io
import logging
import tempfile
import time
from pathlib import Path

from pickplace.v1 import common_pb2, task_pb2
from rich.console import Console

from services.common.modes import TaskKind
from services.common.net import free_loopback_port
from services.common.sensors import RGBDFrame
from services.common.settings import Settings, load_settings
from services.record.service import Kind, RecordService

log = logging.getLogger("pickplace.bench.record")

MINUTE_S = 60.0
JOINT_HZ = 125.0
VISION_HZ = 5.0
N_CYCLES = 3  # per arm, the same seeded scenes with and without recording


def _frames(n: int) -> list[RGBDFrame]:
    from services.vision.synthetic import NoiseModel, d435_intrinsics, render_scene
    from services.vision.synthetic_scenes import random_scene

    intr = d435_intrinsics(640, 480)
    scenes = [
        random_scene(100 + k, cube_colors=("red", "blue"), obstacle=True, intrinsics=intr) for k in range(n)
    ]
    return [render_scene(s, NoiseModel(), seed=k).frame for k, s in enumerate(scenes)]


def _settings(tmp: Path, **record: object) -> Settings:
    return load_settings(
        "sim",
        overrides={
            "logging": {"file": str(tmp / "bench.log")},
            "zenoh": {"listen": [f"tcp/127.0.0.1:{free_loopback_port()}"]},
            "record": {"foxglove": {"port": 0}, **record},
        },
    )


async def _one_minute(settings: Settings, live: bool, record_dir: Path | None) -> float:
    frames = _frames(4)
    names = [f"joint{i + 1}" for i in range(6)]
    svc = RecordService(settings, None, live=live, record_dir=record_dir)
    cpu0 = time.process_time()
    async with svc:
        n_joint = int(MINUTE_S * JOINT_HZ)
        per_frame = int(JOINT_HZ / VISION_HZ)
        for i in range(n_joint):
            t = i / JOINT_HZ
            js = common_pb2.JointState(
                header=common_pb2.Header(stamp_ns=int(t * 1e9), seq=i),
                name=names,
                position=[0.3 * (t % 3.0)] * 6,
                velocity=[0.3] * 6,
                robot_mode=7,
                source_stamp_ns=int(t * 1e9),
            )
            svc.submit(Kind.JOINTS, js.SerializeToString(), wait=True)
            if i % per_frame == 0:
                k = i // per_frame
                f = frames[k % len(frames)]
                svc.offer_frame(
                    RGBDFrame(f.color, f.depth, f.intrinsics, f.depth_scale, int(t * 1e9), "camera", k)
                )
                while svc.frames_waiting:  # noqa: ASYNC110 — the slot holds two: let the converter take each
                    await asyncio.sleep(0.001)
            if i % int(JOINT_HZ / 2) == 0:
                st = task_pb2.TaskStatus(state="APPROACH", progress=(t % 10) / 10, running=True)
                svc.submit(Kind.TASK_STATUS, st.SerializeToString(), wait=True)
            if i % int(JOINT_HZ) == 0:
                log.info("a log line a second (%d)", i)
    return time.process_time() - cpu0


async def _cycles(settings: Settings, record_dir: Path | None) -> tuple[list[float], list[float], list[bool]]:
    from services.apps.cell import Cell, with_updates
    from services.apps.record_cli import cell_live_view

    s = with_updates(
        settings,
        grpc={"robot_port": 0, "motion_port": 0, "grasp_port": 0, "vision_port": 0, "task_port": 0},
        sim={"dashboard_port": 0, "feedback_port": 0, "slow_feedback_port": 0},
        record={"dir": str(record_dir) if record_dir else None},
    )
    s = s.model_copy(
        update={
            "record": s.record.model_copy(
                update={"foxglove": s.record.foxglove.model_copy(update={"enabled": False})}
            )
        }
    )
    controller, wall, ok = [], [], []
    async with Cell(s, seed=3) as cell, cell_live_view(cell, Console(file=io.StringIO())):
        for k in range(N_CYCLES):
            if k:
                await cell.reset_scene(3 + k)
            t0 = time.perf_counter()
            outcome = await cell.task.runner.run_cycle(TaskKind.STAND_ROD)  # type: ignore[union-attr]
            wall.append(time.perf_counter() - t0)
            if not outcome.success:
                print(f"  cycle on seed {3 + k} failed ({outcome.stage_reached}: {outcome.failure_reason})")
            controller.append(outcome.cycle_time_s)
            ok.append(outcome.success)
    return controller, wall, ok


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for label, live, rec, depth in (
            ("recording", False, tmp / "rec", True),
            ("recording, no depth", False, tmp / "rec_nodepth", False),
            ("recording + live view", True, tmp / "rec_live", True),
            ("live view only, no client", True, None, True),
        ):
            cpu = asyncio.run(_one_minute(_settings(tmp, depth=depth), live, rec))
            size = sum(p.stat().st_size for p in rec.glob("*.mcap")) if rec is not None else 0
            mb = f", {size / 1e6:.1f} MB per minute" if rec is not None else ""
            print(
                f"{label:28s}: {cpu:.2f} s CPU per minute of cell data = {100 * cpu / MINUTE_S:.1f} % of one core{mb}"
            )
        base = asyncio.run(_cycles(_settings(tmp), None))
        recd = asyncio.run(_cycles(_settings(tmp), tmp / "cycles"))
    for label, (ctrl, wall, ok) in (("without recording", base), ("with recording", recd)):
        print(
            f"{label:18s}: {sum(ok)}/{len(ok)} cycles succeeded; controller-clock cycle times "
            + ", ".join(f"{c:.2f}" + ("" if good else " (failed)") for c, good in zip(ctrl, ok, strict=True))
            + f" s; {sum(wall) / len(wall):.2f} s wall on average"
        )
    paired = [
        100 * (r / b - 1)
        for r, b, r_ok, b_ok in zip(recd[0], base[0], recd[2], base[2], strict=True)
        if r_ok and b_ok
    ]
    if not paired:
        print("no scene seed with a successful cycle both with and without recording: nothing to compare")
        return
    print(
        "recording vs not, same scene seeds, both successful: "
        + ", ".join(f"{d:+.1f} %" for d in paired)
        + f" (mean {sum(paired) / len(paired):+.1f} %, target ≤ +2 %; the spread is the twin's run-to-run noise)"
    )


if __name__ == "__main__":
    main()
