"""``pickplace eval``: seeded trials of the whole cell in the twin, judged by ground truth.

Every trial lays out a new seeded scene (rod pose in the pick zone, cube layout),
runs one cycle through every service exactly as ``pickplace up`` does (the twin's
depth noise on, the calibration file — optionally with an injected error), lets the
objects settle, and checks the result with the twin's ground truth. Reports success
rate, cycle time and compute time, failures by stage and reason, and intermediate
metrics (tilt before release, tilt after release).

Times: the cycle and every state on the controller's clock (the feedback TimeStamp,
which the simulator keeps in sim time whatever the machine's load), the compute of
the critical path (DETECT + PLAN) in wall time beside it, and the bound: the
time-optimal jerk-limited (ruckig) duration of the executed joint waypoints at the
robot's limits, resting where the arm rested and flowing through the rest (each joint on its own,
at zero speed only where it turns back, swinging through: ``services.motion.bound``), a guarded
touch-down no faster than its tool pace allows (``services.task.pacing.LinePace``: the approach speed
above its slow band, the touch speed through it, the tool's speed changes between; ``bound_pace_s`` is
what that adds), plus the gripper's actuation time per action (its release time for an open that lets
go of the placed object). Beside it, the same waypoints at rest at each
(``bound_rest_to_rest_motion_s``), and the bound without the jerk limit (``bound_accel_limited_s``:
straight lines are timed without it, so it is what no motion the driver lets through can beat). Of
the compute, the twin camera rendering the frames the cycle waited for is told apart
(``camera_wall_s``): on this machine's CPU it is most of DETECT, where a real camera streams its frames.
``load`` runs that many busy processes beside the cell (always ended with the run).
A trial whose harness fails (a scene that cannot be laid out, an exception) is
recorded as a harness error with its reason, and the run goes on.

Worlds: by default every trial's twin is its own randomized world (``sim.twin.randomization``: rod size
and mass, frictions, table height, grip force, the drive's tracking and latency, camera mount,
intrinsics, depth noise, light), seeded from the trial's seed and recorded in the trial's JSON; the cell
is told none of it. ``randomize=False`` (``--nominal``) runs every trial in the configured world. The
report (``eval_report``) gives the success rate with its 95 % Wilson interval and the success per bin of
each randomized parameter. ``calibration_error`` perturbs the nominal camera pose the cell is given; in a
randomized world the camera's own mount error comes on top of it.
"""

from __future__ import annotations

import contextlib
import json
import logging
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import TypedDict

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from services.apps.cell import Cell
from services.apps.eval_journal import TrialJournal
from services.apps.eval_report import BinStat, _p95, sensitivity, wilson_interval
from services.apps.eval_report import print_report as print_report
from services.apps.eval_report import write_report as write_report
from services.common.modes import TaskKind
from services.common.priority import process_nice
from services.common.settings import Settings
from services.kinematics import analytic
from services.kinematics.robot_models import RobotSpec, get_robot
from services.kinematics.trajectory import JointLimits
from services.task.pacing import LinePace
from services.task.states import CycleState, PickOutcome

log = logging.getLogger("pickplace.eval")

SETTLE_S = 1.0  # sim seconds the objects get before the ground-truth check ...
MAX_SETTLE_S = 5.0  # ... and at most this long, in steps, while the placed object still moves
SETTLE_STEP_S = 0.25
COMPUTE_STAGES = ("DETECT", "PLAN")  # the states that compute rather than move
HARNESS_STAGE = "HARNESS"  # stage_reached of a trial the harness could not run
# a busy process at the nice value ordinary work on this machine has (the cell's own may be lower)
BUSY_LOOP = """
import os, sys
try:
    os.setpriority(os.PRIO_PROCESS, 0, int(sys.argv[1]))
except OSError:
    pass
while True:
    pass
"""


@dataclass
class TrialResult:
    seed: int
    success: bool  # by ground truth
    task_success: bool  # what the orchestrator believed
    stage_reached: str
    failure_reason: str
    error_code: str
    cycle_time_s: float  # on the controller's clock
    compute_wall_s: float  # detect + plan in wall time: what the arm waits for on a real-time cell
    compute_controller_s: float  # the same states on the controller's clock (× the sim speed)
    cycle_time_1x_s: float  # the cycle on a real-time cell with this machine's compute
    attempts: int
    tilt_before_release_deg: float | None = None
    tilt_after_deg: float | None = None
    settle_s: float = 0.0  # sim seconds after the cycle before the placed object was judged
    # of compute_wall_s: the twin's camera rendering the frames the cycle waited for, on this machine's
    # CPU (a real camera streams its frames; the cell's own compute is the rest)
    camera_wall_s: float = 0.0
    ground_truth_reasons: list[str] = field(default_factory=list)
    stage_durations_s: dict[str, float] = field(default_factory=dict)  # per state, controller clock
    stage_wall_s: dict[str, float] = field(default_factory=dict)  # per state, wall time
    bound_s: float | None = None  # time-optimal duration of what was executed (module docstring)
    bound_motion_s: float | None = None
    bound_gripper_s: float | None = None
    bound_pace_s: float | None = None  # guarded lines' tool pace beyond the joints' time (touch-downs)
    bound_accel_limited_s: float | None = None  # the bound without the jerk limit (ExecutionBound)
    bound_rest_to_rest_motion_s: float | None = None  # the motion resting at every waypoint
    executed_waypoints: list[list[float]] = field(default_factory=list)  # rad
    executed_rests: list[bool] = field(default_factory=list)  # per waypoint: the arm rested there
    harness_error: str = ""
    scene_redraws: int = 0  # layouts the scene sampler drew again before every object fitted
    randomization: dict[str, float] = field(default_factory=dict)  # this trial's world (empty: nominal)

    @property
    def bound_ratio(self) -> float | None:
        return self.cycle_time_s / self.bound_s if self.bound_s else None


class EvalSummary(TypedDict):
    task: str
    trials: int
    seed: int
    load: int
    cell_nice: int | None  # the nice value the cell ran at (robot.process_nice), the load's beside it
    load_nice: int | None
    success_rate: float
    success_ci95: tuple[float, float]  # Wilson score interval
    randomized: bool
    harness_errors: int
    cycle_time_median_s: float | None
    cycle_time_p95_s: float | None
    cycle_time_1x_median_s: float | None
    compute_wall_median_s: float | None
    compute_share_of_cycle: float | None
    camera_wall_median_s: float | None  # of the compute: the twin camera's frames (TrialResult)
    cell_compute_share_of_cycle: float | None  # the compute without them
    bound_median_s: float | None
    bound_pace_median_s: float | None  # of the bound: touch-downs' pace beyond the joints' time
    bound_ratio_median: float | None
    bound_ratio_p95: float | None
    accel_limited_bound_ratio_median: float | None  # against the bound without the jerk limit
    stage_median_s: dict[str, float]
    failures: dict[str, int]
    sim_speed_achieved: float | None
    sim_late_ticks: int
    wall_time_s: float
    randomization_ranges: dict[str, tuple[float, float]]
    sensitivity: dict[str, list[BinStat]]


@dataclass
class EvalReport:
    task: str
    trials: int
    seed: int
    load: int = 0
    cell_nice: int | None = None
    load_nice: int | None = None
    successes: int = 0
    results: list[TrialResult] = field(default_factory=list)
    wall_time_s: float = 0.0
    sim_speed_achieved: float | None = None  # sim time per wall time over the whole run
    sim_late_ticks: int = 0
    randomized: bool = False
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)  # of each randomization record

    @property
    def success_rate(self) -> float:
        return self.successes / len(self.results) if self.results else 0.0

    def summary(self) -> EvalSummary:
        ran = [r for r in self.results if not r.harness_error]
        ok = [r for r in ran if r.success]
        cycles = [r.cycle_time_s for r in ok]
        compute = [r.compute_wall_s for r in ran]
        camera = [r.camera_wall_s for r in ran]
        cycle_1x = [r.cycle_time_1x_s for r in ran]
        ratios = [x for r in ok if (x := r.bound_ratio) is not None]
        bounds = [r.bound_s for r in ok if r.bound_s is not None]
        paces = [r.bound_pace_s for r in ok if r.bound_pace_s is not None]
        unjerked = [r.cycle_time_s / r.bound_accel_limited_s for r in ok if r.bound_accel_limited_s]
        fails = Counter(
            f"{r.stage_reached}: {r.error_code or 'ground truth'}" for r in self.results if not r.success
        )
        return {
            "task": self.task,
            "trials": len(self.results),
            "seed": self.seed,
            "load": self.load,
            "cell_nice": self.cell_nice,
            "load_nice": self.load_nice,
            "success_rate": self.success_rate,
            "success_ci95": wilson_interval(self.successes, len(self.results)),
            "randomized": self.randomized,
            "harness_errors": len(self.results) - len(ran),
            "cycle_time_median_s": statistics.median(cycles) if cycles else None,
            "cycle_time_p95_s": _p95(cycles),
            "cycle_time_1x_median_s": statistics.median(r.cycle_time_1x_s for r in ok) if ok else None,
            "compute_wall_median_s": statistics.median(compute) if compute else None,
            # what the arm waits for on a real-time cell, as a share of that cell's cycle
            "compute_share_of_cycle": (sum(compute) / sum(cycle_1x)) if sum(cycle_1x) > 0 else None,
            "camera_wall_median_s": statistics.median(camera) if camera else None,
            "cell_compute_share_of_cycle": (
                (sum(compute) - sum(camera)) / sum(cycle_1x) if sum(cycle_1x) > 0 else None
            ),
            "bound_median_s": statistics.median(bounds) if bounds else None,
            "bound_pace_median_s": statistics.median(paces) if paces else None,
            "bound_ratio_median": statistics.median(ratios) if ratios else None,
            "bound_ratio_p95": _p95(ratios),
            "accel_limited_bound_ratio_median": statistics.median(unjerked) if unjerked else None,
            "stage_median_s": self.stage_medians(),
            "failures": dict(fails.most_common()),
            "sim_speed_achieved": self.sim_speed_achieved,
            "sim_late_ticks": self.sim_late_ticks,
            "wall_time_s": self.wall_time_s,
            "randomization_ranges": self.ranges if self.randomized else {},
            "sensitivity": (
                sensitivity([(r.randomization, r.success) for r in ran if r.randomization], self.ranges)
                if self.randomized
                else {}
            ),
        }

    def stage_medians(self) -> dict[str, float]:
        """Median controller-clock duration of each state over the successful trials, in cycle order."""
        ok = [r.stage_durations_s for r in self.results if r.success]
        keys = list(dict.fromkeys(k for d in ok for k in d))
        medians = {k: round(statistics.median(d.get(k, 0.0) for d in ok), 3) for k in keys}
        return {k: v for k, v in medians.items() if v > 0}  # a state most cycles never enter says nothing

    def to_json(self) -> str:
        trials = [{**asdict(r), "bound_ratio": r.bound_ratio} for r in self.results]
        return json.dumps({"summary": self.summary(), "trials": trials}, indent=2)


@dataclass(frozen=True)
class ExecutionBound:
    """What the executed plan needs at least at the robot's limits (module docstring), in seconds."""

    motion_s: float  # resting where the arm rested, flowing through the rest
    gripper_s: float
    rest_to_rest_motion_s: float  # resting at every waypoint (ruckig, all joints in step)
    pace_s: float = 0.0  # what guarded lines need beyond motion_s at their tool pace (touch-downs)
    # the same without the jerk limit, which lines are timed without (services.motion.planner): what
    # no motion the driver lets through (speed and acceleration checked) can beat
    accel_limited_s: float = 0.0

    @property
    def total_s(self) -> float:
        return self.motion_s + self.pace_s + self.gripper_s


def execution_bound(
    waypoints: list[list[float]],
    rests: list[bool],
    limits: JointLimits,
    joint_names: list[str],
    gripper_actions: int,
    actuation_s: float,
    releases: int = 0,
    release_s: float = 0.0,
    line_floors: Mapping[int, float] | None = None,
) -> ExecutionBound:
    """The executed joint waypoints timed time-optimally and jerk-limited (ruckig) at ``limits``, at rest
    where ``rests`` says the arm rested (:func:`services.motion.bound.stop_to_stop_s`; every waypoint
    when it says nothing), plus ``actuation_s`` per gripper action that moved the jaws (as recorded:
    :class:`services.task.recording.RecordingRobot`), of which ``releases`` (opens that
    let go of a held object) take ``release_s``. ``line_floors``: what each guarded line (a touch-down,
    by the index of the waypoint it ended at) needs at least at its tool pace (:func:`line_floors`); the
    excess over the joints' time is ``pace_s``."""
    from services.motion.bound import stop_to_stop_s
    from services.motion.timing import rest_to_rest

    if len(waypoints) < 2:
        motion = each = paced = unjerked = 0.0
    else:
        each = rest_to_rest(waypoints, limits, joint_names).duration
        flags = rests if len(rests) == len(waypoints) else [True] * len(waypoints)
        motion = stop_to_stop_s(waypoints, flags, limits)
        paced = stop_to_stop_s(waypoints, flags, limits, floors=line_floors) if line_floors else motion
        unjerked = stop_to_stop_s(waypoints, flags, replace(limits, max_jerk=None), floors=line_floors)
    gripper = (gripper_actions - releases) * actuation_s + releases * release_s
    return ExecutionBound(motion, gripper, each, paced - motion, unjerked + gripper)


def line_floors(
    waypoints: list[list[float]], paces: Mapping[int, LinePace], spec: RobotSpec
) -> dict[int, float]:
    """For each guarded line that ended at waypoint ``i`` (``paces``), the least time its tool pace
    allows from the waypoint before to there (:meth:`services.task.pacing.LinePace.least_s`). The line
    keeps the tool's orientation, so the flange goes as far as the tool."""
    floors: dict[int, float] = {}
    for i, pace in paces.items():
        if 0 < i < len(waypoints):
            ends = analytic.fk(spec, np.asarray([waypoints[i - 1], waypoints[i]], dtype=float))[:, :3, 3]
            floors[i] = pace.least_s(float(np.linalg.norm(ends[1] - ends[0])))
    return floors


@contextlib.contextmanager
def busy_processes(n: int, nice: int) -> Iterator[list[subprocess.Popen[bytes]]]:
    """``n`` CPU-bound processes beside the cell at ``nice`` (ordinary work's, not the cell's they would
    inherit), ended (each by its own id) however the run ends."""
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for _ in range(n):
            procs.append(
                subprocess.Popen([sys.executable, "-c", BUSY_LOOP, str(nice)], stdin=subprocess.DEVNULL)
            )
        if procs:
            log.info("load: %d busy processes at nice %d %s", n, nice, [p.pid for p in procs])
        yield procs
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            with contextlib.suppress(Exception):
                p.wait(timeout=5.0)


async def run_eval(
    settings: Settings,
    trials: int,
    seed: int,
    task: str = TaskKind.STAND_ROD,
    calibration_error: tuple[float, float] | None = None,
    console: Console | None = None,
    progress: bool = True,
    load: int = 0,
    randomize: bool = True,
    journal: TrialJournal | None = None,
    load_nice: int | None = None,
) -> EvalReport:
    """``journal``: each finished trial is appended to it as it ends, and the trials it already holds
    (a resumed run) are taken from it instead of run again. ``load_nice``: the load's nice value (by
    default this process's: `pickplace eval` passes the one it had before it favoured the cell)."""
    from services.sim.twin.randomization import record_ranges

    s = settings.model_copy(
        update={"task": settings.task.model_copy(update={"reset_scene_each_cycle": False, "task": task})}
    )
    s = _with_randomization(s, randomize)
    report = EvalReport(
        task=task,
        trials=trials,
        seed=seed,
        load=load,
        cell_nice=process_nice(),
        load_nice=(process_nice() if load_nice is None else load_nice) if load else None,
        randomized=randomize,
        ranges=record_ranges(s.sim.twin) if randomize else {},
    )
    spec = get_robot(s.robot.model)
    trial = _TrialRunner(s, task, spec)
    t_start = time.perf_counter()
    calibrated = calibration_error is not None
    # its own state directory (the task's cycle journal): never the cell's, nor another eval's beside it
    # (two evals at once renamed each other's journal, and the second took the first's cycle in progress
    # for one a crash had cut)
    with (
        tempfile.TemporaryDirectory(prefix="pickplace-eval-") as state_dir,
        busy_processes(load, report.load_nice or 0),
    ):
        s = s.model_copy(update={"state": s.state.model_copy(update={"dir": state_dir})})
        # no live vision loop: the trials follow each other as `pickplace up`'s cycles do, and there the
        # loop pauses from the first cycle to the last. Between trials (the judge's settle, the next
        # world) it took frames a continuous run does not: a capture still in flight held up the next
        # DETECT, and the frames it took decided which noise that DETECT's picture got
        async with Cell(
            s,
            seed=seed,
            perfect_calibration=calibrated,
            calibration_error=calibration_error,
            live_vision=False,
        ) as cell:
            sim_t0 = cell.sim_time()
            await trial.run_all(cell, report, trials, seed, console, progress, journal)
            wall = time.perf_counter() - t_start
            report.sim_speed_achieved = (cell.sim_time() - sim_t0) / wall if wall > 0 else None
            report.sim_late_ticks = cell.sim_late_ticks
    report.wall_time_s = time.perf_counter() - t_start
    return report


@dataclass
class _TrialRunner:
    settings: Settings
    task: str
    spec: RobotSpec
    tilt_at_release: list[float] = field(default_factory=list)

    @property
    def limits(self) -> JointLimits:
        return JointLimits.from_spec(self.spec)

    async def run_all(
        self,
        cell: Cell,
        report: EvalReport,
        trials: int,
        seed: int,
        console: Console | None,
        progress: bool,
        journal: TrialJournal | None = None,
    ) -> None:
        assert cell.task is not None and cell.truth is not None  # a twin Cell starts both on entry
        runner = cell.task.runner
        truth = cell.truth

        def on_state(state: CycleState, msg: str) -> None:
            if state is CycleState.RELEASE and self.task == TaskKind.STAND_ROD:
                self.tilt_at_release.append(truth.object_tilt_deg("rod"))
            runner._on_state(state, msg)

        runner.orchestrator._on_state = on_state
        bar = Progress(
            TextColumn("[bold]eval[/bold] {task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[rate]}"),
            TimeRemainingColumn(),
            console=console or Console(),
            disable=not progress,
        )
        with bar:
            job = bar.add_task(self.task, total=trials, rate="")
            done = journal.done_by_seed() if journal else {}
            for i in range(trials):
                self.tilt_at_release.clear()
                if (earlier := done.get(seed + i)) is not None:  # judged by the run this one resumes
                    report.results.append(earlier)
                    report.successes += int(earlier.success)
                    bar.update(job, advance=1, rate=f"{report.successes}/{i + 1} ok")
                    continue
                try:
                    if i > 0:  # the cell starts in the scene of ``seed``
                        await cell.reset_scene(seed + i)
                    camera_before = _camera_s(cell)
                    outcome = await runner.run_cycle(self.task)
                    res = await self.judge(cell, seed + i, outcome)
                    res.camera_wall_s = _camera_s(cell) - camera_before
                except Exception as exc:  # the trial's boundary: one broken trial never ends the run
                    log.warning("trial %d (seed %d): harness error: %s", i, seed + i, exc, exc_info=True)
                    res = _harness_error(seed + i, exc)
                    res.randomization = _world_record(cell, seed + i)
                report.results.append(res)
                report.successes += int(res.success)
                if journal is not None:
                    journal.append(res)
                bar.update(job, advance=1, rate=f"{report.successes}/{i + 1} ok")

    async def judge(self, cell: Cell, seed: int, outcome: PickOutcome) -> TrialResult:
        assert cell.truth is not None
        settled_s = await _settle_until_rest(cell, _placed_object(self.task, outcome.object_class))
        if self.task == TaskKind.STAND_ROD:
            check = cell.truth.rod_standing()
            ok, reasons, tilt_after = check.success, list(check.reasons), check.tilt_deg
        else:
            color = outcome.object_class.removeprefix("cube_")
            cube = cell.truth.cube_in_zone(color) if outcome.object_class.startswith("cube_") else None
            ok = bool(cube and cube.success)
            reasons = list(cube.reasons) if cube else ["no cube was picked"]
            tilt_after = None
        d, w = outcome.stage_durations_s, outcome.stage_wall_s
        compute_wall = sum(w.get(k, 0.0) for k in COMPUTE_STAGES) + outcome.inline_compute_wall_s
        compute_ctrl = sum(d.get(k, 0.0) for k in COMPUTE_STAGES) + outcome.inline_compute_s
        bound = execution_bound(
            outcome.executed_waypoints,
            outcome.executed_rests,
            self.limits,
            list(self.spec.joint_names),
            outcome.gripper_actions,
            self.settings.gripper.actuation_time_s,
            outcome.gripper_releases,
            self.settings.gripper.release_wait_s,
            line_floors(outcome.executed_waypoints, outcome.executed_paces, self.spec),
        )
        return TrialResult(
            seed=seed,
            success=ok,
            task_success=outcome.success,
            stage_reached=outcome.stage_reached,
            failure_reason=outcome.failure_reason or ("; ".join(reasons) if not ok else ""),
            error_code=outcome.error_code if not outcome.success else ("" if ok else "GroundTruth"),
            cycle_time_s=outcome.cycle_time_s,
            compute_wall_s=compute_wall,
            compute_controller_s=compute_ctrl,
            cycle_time_1x_s=outcome.cycle_time_s - compute_ctrl + compute_wall,
            attempts=outcome.attempts,
            tilt_before_release_deg=self.tilt_at_release[-1] if self.tilt_at_release else None,
            tilt_after_deg=tilt_after,
            settle_s=settled_s,
            ground_truth_reasons=reasons,
            stage_durations_s={k: round(v, 4) for k, v in d.items()},
            stage_wall_s={k: round(v, 4) for k, v in w.items()},
            bound_s=bound.total_s,
            bound_motion_s=bound.motion_s,
            bound_gripper_s=bound.gripper_s,
            bound_pace_s=bound.pace_s,
            bound_accel_limited_s=bound.accel_limited_s,
            bound_rest_to_rest_motion_s=bound.rest_to_rest_motion_s,
            executed_waypoints=outcome.executed_waypoints,
            executed_rests=outcome.executed_rests,
            scene_redraws=cell.truth.scene_record().layout_redraws,
            randomization=_world_record(cell, seed),
        )


def _with_randomization(settings: Settings, enabled: bool) -> Settings:
    twin = settings.sim.twin
    rnd = twin.randomization.model_copy(update={"enabled": enabled})
    sim = settings.sim.model_copy(update={"twin": twin.model_copy(update={"randomization": rnd})})
    return settings.model_copy(update={"sim": sim})


def _world_record(cell: Cell, seed: int) -> dict[str, float]:
    """The randomization record of the world the trial of ``seed`` ran in ({} when nominal or unknown)."""
    if cell.truth is None:  # no twin engine (yet): nothing to record
        return {}
    try:
        scene = cell.truth.scene_record()
    except (AssertionError, AttributeError, OSError, RuntimeError):  # no engine (yet) or no sim: none
        return {}
    return scene.randomization if scene.seed == seed else {}


def _camera_s(cell: Cell) -> float:
    """Wall seconds the cell's camera has spent on frames someone waited for, so far."""
    return cell.vision.waited_capture_s if cell.vision is not None else 0.0


def _harness_error(seed: int, exc: BaseException) -> TrialResult:
    reason = f"{type(exc).__name__}: {exc}"
    return TrialResult(
        seed=seed,
        success=False,
        task_success=False,
        stage_reached=HARNESS_STAGE,
        failure_reason=reason,
        error_code="HarnessError",
        cycle_time_s=0.0,
        compute_wall_s=0.0,
        compute_controller_s=0.0,
        cycle_time_1x_s=0.0,
        attempts=0,
        harness_error=reason,
    )


def _placed_object(task: str, object_class: str) -> str | None:
    if task == TaskKind.STAND_ROD:
        return "rod"
    return object_class if object_class.startswith("cube_") else None


async def _settle_until_rest(cell: Cell, name: str | None) -> float:
    """Let the cell run SETTLE_S, then longer while ``name`` still moves (a rod released a few degrees
    off vertical rocks back onto its base for a while): judged at rest, not mid-rock. Returns the
    sim seconds waited; a still-moving object after MAX_SETTLE_S is judged as it is."""
    from services.sim.twin import ground_truth as gt

    assert cell.truth is not None
    await cell.settle(SETTLE_S)
    waited = SETTLE_S
    while name is not None and waited < MAX_SETTLE_S:
        lin, ang = cell.truth.object_velocity(name)
        if lin < gt.REST_LINEAR_M_S and ang < gt.REST_ANGULAR_RAD_S:
            break
        await cell.settle(SETTLE_STEP_S)
        waited += SETTLE_STEP_S
    return waited
