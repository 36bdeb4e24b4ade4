"""The pick cycle: INIT → DETECT → PLAN → APPROACH → GRASP → LIFT → REORIENT → PLACE →
RELEASE → DONE, with DETECT_FAILED → RETRY → ABORT and the recovery of LLD §15.2.

The orchestrator only awaits its ports (never blocks the event loop), runs every state
under a deadline, times each stage, and resumes from the failed step: a failed
detection looks again, an unplannable grasp tries the next option, a robot alarm is
cleared and the rest is replanned from where the arm stands (the object still in the
gripper if it was carried), a grasp that did not hold is retried with an adjusted grasp,
and a safety stop hands over to the operator.

Its waits and its clocks are injected (``wait``, ``clock``, ``wall_clock``): stage and cycle
durations are on ``clock`` — the controller's clock in the cell (its feedback TimeStamp), the fake
controller's time in tests — and each state's wall time (what computing costs) on ``wall_clock``.
Between cycles no state runs: the gap is charged to none.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
import uuid
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TypeVar, cast

import numpy as np

from services.common.errors import (
    ContactAlarmError,
    ContinuationLateError,
    ControllerError,
    GraspFailureError,
    ObjectNotDetectedError,
    PathDeviationError,
    PlanningError,
    RobotError,
    SafetyError,
    StartMismatchError,
    VisionError,
)
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.kinematics.trajectory import JointTrajectory
from services.task.cycle_config import CycleConfig
from services.task.deadline import within
from services.task.flow_on import FLOWS_ON_BELOW_RATE
from services.task.moves import (
    grasp_approach,
    is_last_of,
    joined,
    move_to,
    placed_box,
    raise_waypoint,
    raised,
    run_end,
    seen_higher,
    sent_along,
)
from services.task.pick_planning import RESUME_TOLERANCE_RAD, PickPlanning, near
from services.task.plan import state_for
from services.task.planned import PlannedPick, Progress
from services.task.ports import (
    ArmView,
    GraspPort,
    MotionPort,
    Move,
    MoveOutcome,
    Observation,
    RobotPort,
    SeenBox,
    SeenRod,
    VisionPort,
)
from services.task.recording import RecordingRobot
from services.task.recovery import Action, Attempts, decide
from services.task.set_off_run import SetOffRun
from services.task.states import CycleState, PickOutcome
from services.task.straighten import held_rod_query, straightening, turn_from, turned

log = logging.getLogger("pickplace.task.cycle")
LIFT_CHECK_FAILED = (
    "grasp verification after LIFT: the object is not in the gripper as the arm passed the lift's end"
)

T = TypeVar("T")
BACK_OFF_M = 0.08  # straight up out of a failed grasp before the way home

StateListener = Callable[[CycleState, str], None]
Wait = Callable[[float], Awaitable[None]]


@dataclass(frozen=True)
class SetOff:
    """The arm on its way to above the object while the grasp plans: the move under way, and the run
    that sends it (where it goes from and to, and whether it went on down the grasp line)."""

    moving: asyncio.Future[MoveOutcome]
    run: SetOffRun

    @property
    def start(self) -> np.ndarray:
        return self.run.start

    @property
    def end(self) -> np.ndarray:
        return self.run.end


class CycleAborted(Exception):
    """The cycle gave up; the outcome says why."""


class Orchestrator:
    def __init__(
        self,
        vision: VisionPort,
        grasp: GraspPort,
        motion: MotionPort,
        robot: RobotPort,
        config: CycleConfig | None = None,
        on_state: StateListener | None = None,
        wait: Wait = asyncio.sleep,
        clock: Callable[[], float] = time.perf_counter,
        wall_clock: Callable[[], float] = time.perf_counter,
        view: ArmView | None = None,
    ):
        self.vision, self.grasp, self.motion, self.robot = vision, grasp, motion, robot
        self.config = config or CycleConfig()
        self._on_state = on_state
        self._wait = wait  # between detection retries
        self._clock = clock  # stage and cycle durations (the controller's clock in the cell)
        self._wall_clock = wall_clock  # the wall time of each state beside it (compute runs on it)
        self.state = CycleState.IDLE
        self._outcome: PickOutcome | None = None
        self._stage_t0: tuple[float, float] | None = None  # (clock, wall) at entry; None between cycles
        self._progress = Progress()
        # the last trajectory sent ends in motion and the next has not been sent: the arm flows on
        # through queued targets, and a failed step must stop it rather than let the stream run dry
        self._flowing = False
        # the grasp check after a LIFT the arm flows on from: the object sensor as the arm passes the
        # lift's end, read while what follows is queued (None: no check waiting)
        self._lift_check: asyncio.Future[bool | None] | None = None
        self._grasp_raise_m = 0.0  # this cycle's next grasps go this much higher than seen
        self._set_off: SetOff | None = None  # the move toward the object while its grasp plans
        self._cycle_start = (0.0, 0.0)  # (clock, wall) at the cycle's start
        # the grasp and motion planners, and the arm against the camera's view of the pick zone
        self._planning = PickPlanning(grasp, motion, self.config, view)

    # ------------------------------------------------------------------ bookkeeping
    @property
    def current(self) -> PickOutcome | None:
        """The outcome of the cycle in progress as it stands (None between cycles)."""
        return self._outcome

    def _enter(self, state: CycleState, message: str = "") -> None:
        self._close_stage()
        out = self._outcome
        self._stage_t0 = (self._clock(), self._wall_clock())
        self.state = state
        if out is not None and state not in (
            CycleState.ABORT,
            CycleState.DETECT_FAILED,
            CycleState.RETRY,
            CycleState.ESTOP,
            CycleState.ERROR,
        ):
            out.stage_reached = state.value
        log.info("state %s %s", state.value, message)
        if self._on_state is not None:
            self._on_state(state, message)

    def _close_stage(self) -> None:
        """Charge the time since the current state was entered to it (nothing between cycles)."""
        out, t0 = self._outcome, self._stage_t0
        if out is None or t0 is None or self.state is CycleState.IDLE:
            return
        key = self.state.value
        out.stage_durations_s[key] = out.stage_durations_s.get(key, 0.0) + (self._clock() - t0[0])
        out.stage_wall_s[key] = out.stage_wall_s.get(key, 0.0) + (self._wall_clock() - t0[1])
        self._stage_t0 = None

    async def _timed(
        self, aw: Awaitable[T], seconds: float, what: str, error: type[RobotError] = RobotError
    ) -> T:
        """Compute (detection, planning) under a wall-clock deadline: it runs on this machine's time;
        past it, ``error`` (a detection that ran late is a VisionError: looked at again, not given up)."""
        try:
            async with asyncio.timeout(seconds):
                return await aw
        except TimeoutError:
            raise error(f"{what} did not finish within its {seconds:.0f} s deadline") from None

    async def _arm(self, aw: Awaitable[T], seconds: float, what: str) -> T:
        """What the arm or the gripper does, under a deadline on the controller's clock."""
        return await within(aw, seconds, what, self._clock)

    # ------------------------------------------------------------------ the cycle
    async def run(self, task: TaskKind | str = TaskKind.STAND_ROD) -> PickOutcome:
        task = TaskKind(task)
        t0 = self._clock()
        self._cycle_start = (t0, self._wall_clock())
        out = PickOutcome(pick_id=uuid.uuid4().hex, task=task, object_class=task.object_class)
        self._outcome = out
        self._stage_t0 = None  # what happened since the last cycle belongs to no state of this one
        robot, self.robot = self.robot, cast(RobotPort, RecordingRobot(self.robot, out))
        attempts = Attempts()
        self._grasp_raise_m = 0.0
        self._enter(CycleState.INIT)
        try:
            await self._prepare(out)
            await self._cycle(task, out, attempts)
            out.success = True
            self._enter(CycleState.DONE, "object placed")
        except CycleAborted as exc:
            out.success = False
            out.failure_reason = out.failure_reason or str(exc)
            self._enter(CycleState.ABORT, out.failure_reason)
        except SafetyError as exc:
            out.success = False
            out.failure_reason = str(exc)
            out.error_code = type(exc).__name__
            self._enter(CycleState.ESTOP, str(exc))
            raise
        finally:
            out.attempts = attempts.total
            self._close_stage()
            out.cycle_time_s = self._clock() - t0
            self._outcome = None
            self.robot = robot
        return out

    async def _prepare(self, out: PickOutcome) -> None:
        """Recover the arm and take it home. A fault on the way (the execution monitor stopped the arm,
        say) fails this cycle and the next one tries again, as an aborted step does later in the cycle;
        a safety stop still waits for the operator."""
        try:
            await self._arm(self.robot.recover(), self.config.deadlines.motion_s, "robot preparation")
            await self._go_home()
        except SafetyError:
            raise
        except RobotError as exc:
            out.error_code = type(exc).__name__
            raise CycleAborted(f"{self.state.value}: {exc}") from exc

    async def _cycle(self, task: TaskKind, out: PickOutcome, attempts: Attempts) -> None:
        while True:  # each pass: detect → plan → execute; recovery loops back here
            obs = await self._detect(out, attempts)
            planned = await self._plan_setting_off(task, obs, out, attempts)
            if await self._carry_out(planned, obs, out, attempts):
                return

    async def _plan_setting_off(
        self, task: TaskKind, obs: Observation, out: PickOutcome, attempts: Attempts
    ) -> PlannedPick:
        """PLAN, the arm on its way to above the object meanwhile when a way there was found: only
        what the arm waits for is PLAN (planning that move, and the plan it finds not yet done when it
        arrives); the rest is APPROACH."""
        cfg = self.config
        if cfg.set_off_height_m <= 0:
            return await self._plan(task, obs, out, attempts)
        self._enter(CycleState.PLAN, "setting off toward the object")
        q = await self.robot.joints()
        try:
            move = await self._timed(
                self._planning.set_off(task, obs, q),
                cfg.deadlines.plan_s,
                "planning the set-off",
                PlanningError,
            )
        except PlanningError as exc:  # no time for it: the arm waits for the plan where it is
            log.info("no set-off move: %s", exc)
            move = None
        if move is None:
            return await self._plan(task, obs, out, attempts)
        flows_on = (
            cfg.set_off_flows_on
            and move.on_approach
            and self._clock_rate() < FLOWS_ON_BELOW_RATE
            and await self._jaws_opened()
        )
        run = SetOffRun(move, q, cfg.servo_period_s, flows_on)
        moving = asyncio.ensure_future(
            self._arm(run.run(self.robot), cfg.deadlines.motion_s, "setting off toward the object")
        )
        self._set_off = SetOff(moving, run)
        self._enter(CycleState.APPROACH, "set off toward the object; its grasp plans meanwhile")
        planning = asyncio.ensure_future(self._plan(task, obs, out, attempts, moving=True))
        try:
            await asyncio.wait({planning, moving}, return_when=asyncio.FIRST_COMPLETED)
            if moving.done() and not moving.cancelled() and isinstance(moving.exception(), SafetyError):
                await self._arrived()  # a safety stop on the way: raised now, not after the plan
            if not planning.done():
                self._enter(CycleState.PLAN, "above the object: waiting for its grasp plan")
            planned = await planning
            if not moving.done():  # the rest of the way may flow on down the grasp line
                run.flow_on(self._planning, planned)
            return planned
        except Exception:
            # given up on (or a safety stop): the arm ends the move it is on before anything else
            planning.cancel()
            with contextlib.suppress(RobotError):
                await self._arrived()
            raise
        except BaseException:  # cancelled: so is the move (the robot's stop ends it)
            planning.cancel()
            moving.cancel()
            self._set_off = None
            raise

    def _clock_rate(self) -> float:
        """How fast the controller's clock has run against the host's since the cycle started (a twin at
        ``--speed N``: about N; 1 on a real cell)."""
        wall = self._wall_clock() - self._cycle_start[1]
        return (self._clock() - self._cycle_start[0]) / wall if wall > 0.05 else 1.0

    async def _jaws_opened(self) -> bool:
        """Open the jaws before setting off (the grasp opens them above the object anyway): the set-off
        may then flow on down the grasp line. False when they could not be opened (they open above the
        object then, as the plan says)."""
        try:
            await self._arm(self.robot.gripper(False), self.config.deadlines.gripper_s, "gripper open")
        except SafetyError:
            raise
        except RobotError as exc:
            log.info("jaws not opened before setting off (%s): the arm stops above the object", exc)
            return False
        return True

    async def _arrived(self) -> int | None:
        """The set-off move under way (if any) has ended: its failure is the failure of this step. The
        waypoint it went on to without stopping (the grasp), if it did; a failure on that way down is
        that waypoint's."""
        set_off, self._set_off = self._set_off, None
        if set_off is None:
            return None
        try:
            await set_off.moving
        except BaseException:
            if set_off.run.went_on_to is not None:
                self._progress = Progress(set_off.run.went_on_to)
            raise
        return set_off.run.went_on_to

    async def _carry_out(
        self, planned: PlannedPick, obs: Observation, out: PickOutcome, attempts: Attempts
    ) -> bool:
        """Execute the plan, resuming it after cleared alarms; False: detect and plan again."""
        self._progress = Progress()
        self._flowing = False
        try:
            return await self._carry_out_plan(planned, obs, out, attempts)
        finally:
            planned.cancel()  # a plan given up on stops planning its later moves

    async def _carry_out_plan(
        self, planned: PlannedPick, obs: Observation, out: PickOutcome, attempts: Attempts
    ) -> bool:
        while True:
            try:
                if (went_on_to := await self._arrived()) is not None:
                    # the set-off flowed on down to the grasp: there already, the jaws open
                    planned.trajs[went_on_to] = None
                    self._progress = Progress(went_on_to)
                await self._execute(planned, self._progress)
                if self.state is not CycleState.DONE:  # the plan's way home already entered it
                    self._enter(CycleState.DONE, "placed; the arm leaves the camera's view clear")
                await self._return_home(planned, obs)
                return True
            except SafetyError:
                raise
            except RobotError as exc:
                if self._flowing:
                    # a step failed while the arm flows on (the grasp check during LIFT): stop it now,
                    # not when the stream it was given runs dry and the driver's watchdog stops it
                    self._flowing = False
                    try:
                        await self.robot.stop()
                    except RobotError as stop_exc:  # the driver's watchdog still stops it
                        log.warning("could not stop the arm flowing on after %s: %s", exc, stop_exc)
                i = self._progress.index
                holding = planned.plan.waypoints[i].holding  # the object is carried
                # stopped again on the approach a contact already raised, or pushed off its path on a
                # grasp approach: the fingers press on a neighbour or the object's edge, not on the table
                # (raising more, or resuming, meets it again): another grasp
                again = (i in planned.touched and isinstance(exc, ControllerError)) or (
                    isinstance(exc, PathDeviationError) and grasp_approach(planned.plan, i)
                )
                action = decide(exc, attempts, self.config.limits, holding=holding, another_grasp=again)
                if action is Action.REGRASP and holding and isinstance(exc, GraspFailureError):
                    # held when the jaws closed, gone since: they may have stood on a table higher than
                    # seen, blocked apart beside the object (seed 1122: the same grasp failed 4 times)
                    self._grasp_raise_m += self.config.contact_raise_m
                out.error_code = type(exc).__name__
                log.warning("execution failed in %s: %s → %s", self.state.value, exc, action.value)
                if action is Action.WAIT_FOR_OPERATOR:
                    raise
                if action is Action.ABORT:
                    # a grasp found empty is let go: jaws left closed on a rod that slipped half out
                    # would hold it askew where no next cycle can pick it
                    await self._leave_safe(release=isinstance(exc, GraspFailureError))
                    raise CycleAborted(f"{self.state.value}: {exc}") from exc
                await self.robot.recover()
                if action is Action.CLEAR_AND_RESUME:
                    # the scene is as planned (the object in the gripper if it was carried): go on from
                    # the failed waypoint, its motion replanned from where the arm stands
                    if isinstance(exc, ContactAlarmError) and grasp_approach(planned.plan, i):
                        # the fingertips met the table before the grasp: the table is higher than seen
                        raise_waypoint(planned.plan, i, self.config.contact_raise_m)
                        planned.moved.add(i)
                        planned.touched.add(i)
                    w = planned.plan.waypoints[i]
                    self._enter(state_for(w.name), f"resuming at {w.name} after {type(exc).__name__}")
                    continue
                if action is Action.REGRASP or (action is Action.NEXT_GRASP and self._progress.index > 0):
                    await self._back_off_open(planned)  # out of the grasp and the view before looking again
                return False  # REGRASP / NEXT_GRASP: detect again and plan from where the arm is

    # ------------------------------------------------------------------ DETECT
    async def _detect(self, out: PickOutcome, attempts: Attempts) -> Observation:
        while True:
            self._enter(CycleState.DETECT)
            try:
                obs = await self._timed(
                    self.vision.observe(), self.config.deadlines.detect_s, "detection", VisionError
                )
                if out.task is TaskKind.STAND_ROD and not obs.rods:
                    raise ObjectNotDetectedError(
                        "no rod detected: " + ("; ".join(obs.notes) or "empty table")
                    )
                if out.task is TaskKind.SORT_CUBES and not obs.cubes:
                    raise ObjectNotDetectedError(
                        "no cube detected: " + ("; ".join(obs.notes) or "empty table")
                    )
                return obs
            except RobotError as exc:
                action = decide(exc, attempts, self.config.limits)
                out.error_code = type(exc).__name__
                self._enter(CycleState.DETECT_FAILED, str(exc))
                if action is not Action.RETRY_DETECT:
                    out.failure_reason = f"DETECT: {exc} (after {attempts.detect} retries)"
                    raise CycleAborted(out.failure_reason) from exc
                self._enter(
                    CycleState.RETRY, f"detection retry {attempts.detect}/{self.config.limits.detect}"
                )
                # doubling waits: a restarting vision service or a passing occlusion gets time
                await self._wait(self.config.detect_retry_delay_s * 2 ** (attempts.detect - 1))

    # ------------------------------------------------------------------ PLAN
    async def _plan(
        self, task: TaskKind, obs: Observation, out: PickOutcome, attempts: Attempts, moving: bool = False
    ) -> PlannedPick:
        """The next grasp option that plans; ``moving``: the arm sets off meanwhile (its state is
        APPROACH until it waits for the plan)."""
        while True:
            if not moving:
                self._enter(CycleState.PLAN, f"grasp option {attempts.grasp_variants}")
            try:
                return await self._timed(
                    self._plan_once(task, obs, out, attempts.grasp_variants),
                    self.config.deadlines.plan_s,
                    "planning",
                    PlanningError,  # the next option, or an abort naming it: never an escaped error
                )
            except PlanningError as exc:
                action = decide(exc, attempts, self.config.limits)
                out.error_code = type(exc).__name__
                if action is not Action.NEXT_GRASP:
                    out.failure_reason = f"PLAN: {exc}"
                    if self.state is not CycleState.PLAN:  # the arm was on its way meanwhile
                        self._enter(CycleState.PLAN, str(exc))
                    raise CycleAborted(out.failure_reason) from exc
                log.info("plan option failed (%s); trying the next one", exc)

    async def _plan_once(
        self, task: TaskKind, obs: Observation, out: PickOutcome, alternative: int
    ) -> PlannedPick:
        set_off = self._set_off  # on the way: planned from where that move ends
        q = set_off.end if set_off is not None else await self.robot.joints()
        if self._grasp_raise_m > 0:
            log.info("grasping %.0f mm higher than seen after an emptied grasp", self._grasp_raise_m * 1e3)
            obs = seen_higher(obs, self._grasp_raise_m)
        seen_from = set_off.start if set_off is not None else None
        return await self._planning.plan(task, obs, out, alternative, q, seen_from)

    # ------------------------------------------------------------------ EXECUTE
    async def _replan_run(
        self, planned: PlannedPick, i: int, q_now: np.ndarray, what: str
    ) -> JointTrajectory | None:
        """Plan waypoint ``i`` to the end of its blended run again from ``q_now`` (the arm at rest);
        returns waypoint ``i``'s new trajectory."""
        end = run_end(planned, i)
        again = await self._timed(
            self._planning.motions(planned.plan, range(i, end + 1), q_now, planned.obstacles),
            self.config.deadlines.plan_s,
            what,
        )
        planned.trajs[i : end + 1] = again[i : end + 1]
        return planned.trajs[i]

    async def _execute(self, planned: PlannedPick, resume: Progress) -> None:
        """From waypoint ``resume.index`` on (its motion skipped when the arm had reached it)."""
        try:
            await self._execute_from(planned, resume)
        finally:
            self._drop_lift_check()

    async def _execute_from(self, planned: PlannedPick, resume: Progress) -> None:
        cfg = self.config
        plan = planned.plan
        q_known: np.ndarray | None = None  # where the last move ended (no round trip for the joints)
        in_motion = False  # the last trajectory ends in motion: this one continues it
        along: int | None = None  # the waypoint whose motion went out with the one before it
        for i in range(resume.index, len(plan.waypoints)):
            if i >= planned.rest_from and move_to(plan, i) is not None:
                await planned.settle(cfg.deadlines.plan_s)
            w, traj = plan.waypoints[i], planned.trajs[i]
            if i == along:
                traj = None  # on its way already
            self._progress = Progress(i, reached=i == resume.index and resume.reached)
            state = state_for(w.name)
            if state is not self.state:
                self._enter(state, w.name)
            if w.guard_force_n > 0 and w.holding and cfg.verify_grasp and not self._progress.reached:
                self._settle_lift_check()  # the arm rests above the place: passed the lift's end long ago
                # the fingers may have closed on the table beside the object and slid shut while it
                # turned (seed 1910, a table 4.5 mm above where it was seen): the sensor held until
                # after LIFT; a touch-down with nothing in the jaws would "place" it and report success
                await self._check_holding(f"before the touch-down at {w.name}")
            if w.guard_force_n > 0 and w.holding and not self._progress.reached and not in_motion:
                q_rest = q_known if q_known is not None else await self.robot.joints()
                if (q_turned := await self._straighten(planned, i, q_rest)) is not None:
                    # the touch-down goes turned as the rod was, from where the turn left the arm
                    q_known, w = q_turned, plan.waypoints[i]
                    traj = await self._replan_run(planned, i, q_turned, f"planning {w.name} turned")
            if (
                traj is None
                and i != along
                and not in_motion
                and not self._progress.reached
                and move_to(plan, i) is not None
            ):
                # planned as reached already (the pre-grasp where the set-off ends): unless the arm
                # stopped short of it (an alarm on the way), there is nothing to do
                q_known = q_known if q_known is not None else await self.robot.joints()
                if np.max(np.abs(w.joints - q_known)) > RESUME_TOLERANCE_RAD:
                    traj = await self._replan_run(planned, i, q_known, f"replanning {w.name}")
            if traj is not None and not self._progress.reached and not in_motion:
                # the arm is at rest: jaws that open at a waypoint it will pass without stopping open now
                await self._open_ahead(planned, i)
            continues = traj is not None and traj.ends_in_motion
            if traj is not None and not self._progress.reached:
                q_now = q_known if q_known is not None else await self.robot.joints()
                off = np.max(np.abs(traj.positions[0] - q_now)) > RESUME_TOLERANCE_RAD
                if not in_motion and (off or traj.starts_in_motion):
                    # the arm is not where the plan assumed (a guarded stop, an alarm), or it is at rest
                    # where the plan flows through: replan from here to the end of this blended run
                    traj = await self._replan_run(planned, i, q_now, f"replanning {w.name}")
                    continues = traj is not None and traj.ends_in_motion
                moving_to = w.name
                if traj is not None and not in_motion and (then := sent_along(planned, i)) is not None:
                    # a short move from rest into the next: one call, so the stream never holds less
                    # than the driver keeps ahead of a call that flows on (states and progress: the next's)
                    along, nxt = i + 1, plan.waypoints[i + 1]
                    moving_to = f"{w.name} + {nxt.name}"
                    traj = joined(traj, then)
                    continues = traj.ends_in_motion
                    if (state_along := state_for(nxt.name)) is not self.state:
                        self._enter(state_along, nxt.name)
                    self._progress = Progress(along)
                if traj is not None:
                    self._flowing = False  # what flowed on is continued (or stopped) by this one
                    try:
                        res = await self._arm(
                            self._checked(self.robot.execute(traj, w.guard_force_n, continues=continues)),
                            cfg.deadlines.motion_s,
                            f"motion to {moving_to}",
                        )
                    except (ContinuationLateError, StartMismatchError) as exc:
                        # the motion this one flows from ended before it came (a busy planner, a slow
                        # machine), or the arm rests off the plan's start (seen after a ServoJ stream
                        # resumed from rest on a busy machine): nothing was sent; from here to the end
                        # of the run is planned from rest, once
                        if in_motion and isinstance(exc, StartMismatchError):
                            raise  # off the queued motion still under way: not mended from here
                        log.info("%s: %s", w.name, exc)
                        # the run goes again move by move
                        along, moving_to, self._progress = None, w.name, Progress(i)
                        q_now = await self.robot.joints()
                        traj = await self._replan_run(planned, i, q_now, f"replanning {w.name} from rest")
                        if traj is None:
                            raise
                        continues = traj.ends_in_motion
                        res = await self._arm(
                            self.robot.execute(traj, w.guard_force_n, continues=continues),
                            cfg.deadlines.motion_s,
                            f"motion to {w.name}",
                        )
                    q_known, in_motion = res.final_q, continues
                    self._flowing = continues
                    log.debug(
                        "%s: planned %.2f s, executed %.2f s%s",
                        moving_to,
                        traj.duration,
                        res.duration_s,
                        " (stopped on touch-down)" if res.stopped_early else "",
                    )
                    if (
                        w.guard_force_n > 0
                        and not res.stopped_early
                        and not await self._touch_down_further(planned, i)
                    ):
                        log.warning("%s: no touch-down detected within the overtravel", w.name)
                    if w.guard_force_n > 0:
                        q_known = await self.robot.joints()  # where the arm came to rest after the stop
                    if (w.guard_force_n > 0 or i in planned.moved) and i + 1 < len(plan.waypoints):
                        # what follows starts where the guard stopped (or where a moved waypoint put
                        # the arm): planned while the jaws act
                        planned.plan_rest(
                            i + 1,
                            self._planning.motions(
                                plan, range(i + 1, len(plan.waypoints)), q_known, planned.obstacles
                            ),
                        )
            self._progress = Progress(i, reached=True)
            # an open at a waypoint passed without stopping was done before setting off
            passed = in_motion or along == i + 1
            if w.gripper is not None and not (passed and w.gripper is GripperCommand.OPEN):
                close = w.gripper is GripperCommand.CLOSE
                # letting go of what it set down, the arm may move away once the jaws are clear of it
                release = not close and w.holding
                if release and cfg.verify_grasp and not (i > 0 and plan.waypoints[i - 1].guard_force_n > 0):
                    # no touch-down felt the object (a dropped cube): the cell reports it placed only
                    # if the jaws still hold it as they let go
                    self._settle_lift_check()
                    await self._check_holding(f"before the release at {w.name}")
                g = await self._arm(
                    self.robot.gripper(close, release), cfg.deadlines.gripper_s, f"gripper {w.gripper}"
                )
                if close and g.object_detected is False and cfg.verify_grasp:
                    raise GraspFailureError(f"{w.name}: the gripper closed on nothing")
            if state is CycleState.LIFT and cfg.verify_grasp and is_last_of(plan, i, CycleState.LIFT):
                if in_motion and q_known is not None:
                    # the call answered with the lift still queued ahead of the arm (how far ahead is the
                    # driver's look-ahead): the sensor is read as the controller reports the arm passing
                    # the lift's end, while the turn is queued and flows on (_checked stops it if empty)
                    self._lift_check = asyncio.ensure_future(self.robot.holding_on_passing(q_known))
                else:
                    await self._check_holding("after LIFT")

    async def _touch_down_further(self, planned: PlannedPick, i: int) -> bool:
        """A guarded touch-down that went its whole overtravel without feeling the contact (a table lower,
        or the object held higher, than planned) goes on, guarded, ``touch_down_extension_m`` further
        rather than letting go in the air; True once it touched. A further way it cannot plan (the fingers
        would meet the table) is not taken."""
        cfg = self.config
        w = planned.plan.waypoints[i]
        if cfg.touch_down_extension_m <= 0 or not w.holding:  # only what sets down a carried object
            return False
        q = await self.robot.joints()
        try:
            traj = await self._timed(
                self._planning.further_touch_down(
                    planned.plan, i, q, planned.obstacles, cfg.touch_down_extension_m
                ),
                cfg.deadlines.plan_s,
                f"planning the touch-down at {w.name} further",
                PlanningError,
            )
        except PlanningError as exc:
            log.warning("%s: no touch-down within the overtravel, and no further way down: %s", w.name, exc)
            return False
        if traj is None:
            return False
        log.info(
            "%s: no touch-down within the overtravel: %.0f mm further",
            w.name,
            cfg.touch_down_extension_m * 1e3,
        )
        res = await self._arm(
            self.robot.execute(traj, w.guard_force_n),
            cfg.deadlines.motion_s,
            f"touch-down at {w.name}, further",
        )
        return res.stopped_early

    async def _straighten(self, planned: PlannedPick, i: int, q: np.ndarray) -> np.ndarray | None:
        """Before the touch-down at waypoint ``i`` of a rod grasped off its centre: its axis as vision
        measures it now; leaning more than ``straighten_min_deg``, the tool turns it straight (about the
        jaws) and the touch-down and what follows go turned as much. Where the arm came to rest, or None
        when it did not turn (not measured, straight enough, or a measure not to trust: set down as it is)."""
        cfg = self.config
        if planned.rod is None or cfg.straighten_from_offset_m <= 0:
            return None
        if abs(planned.grasp_offset_m) < cfg.straighten_from_offset_m:
            return None
        out, t0 = self._outcome, (self._clock(), self._wall_clock())
        try:
            found = await self._straightening(planned, planned.rod, q)
        finally:  # measuring and planning: compute the arm waits for, though the state is PLACE
            if out is not None:
                out.inline_compute_s += self._clock() - t0[0]
                out.inline_compute_wall_s += self._wall_clock() - t0[1]
        if found is None:
            return None
        traj, R = found
        turn_from(planned.plan, i, R)
        res = await self._arm(self.robot.execute(traj), cfg.deadlines.motion_s, "straightening the held rod")
        return res.final_q

    async def _straightening(
        self, planned: PlannedPick, rod: SeenRod, q: np.ndarray
    ) -> tuple[JointTrajectory, np.ndarray] | None:
        """The move that turns the held rod straight and the turn (3×3), or None when it should not."""
        cfg = self.config
        try:
            T = await self.motion.tool_pose(q)
            query = held_rod_query(T, rod, planned.grasp_offset_m, cfg.jaw_footprint_m[0], cfg.table_z_m)
            seen = await self._timed(
                self.vision.held_rod_axis(query),
                cfg.deadlines.detect_s,
                "measuring the held rod",
                VisionError,
            )
        except SafetyError:
            raise
        except RobotError as exc:  # no camera, too little of the rod seen, vision down: as it hangs
            log.info("the held rod was not measured (%s): set down as it hangs", exc)
            return None
        if seen.tilt_deg < cfg.straighten_min_deg:
            return None
        if seen.tilt_deg > cfg.straighten_max_deg:
            log.warning(
                "the held rod measured %.1f° off the vertical, beyond %.1f°: taken for a wrong measure, "
                "set down as it hangs",
                seen.tilt_deg,
                cfg.straighten_max_deg,
            )
            return None
        R = straightening(seen.direction)
        move = Move(MotionKind.LINEAR, turned(T, R, T[:3, 3]), planned.plan.held_object, label="STRAIGHTEN")
        try:
            traj = await self._timed(
                self._planning.single(q, move, planned.obstacles),
                cfg.deadlines.plan_s,
                "planning the straightening of the held rod",
                PlanningError,
            )
        except PlanningError as exc:
            log.warning("the held rod leans %.1f° and cannot be turned straight: %s", seen.tilt_deg, exc)
            return None
        if traj is None:
            return None
        log.info("the held rod leans %.2f° (%d points): turned straight", seen.tilt_deg, seen.n_points)
        return traj, R

    async def _checked(self, motion: Awaitable[MoveOutcome]) -> MoveOutcome:
        """``motion``, while the grasp check after LIFT waits for the arm to pass the lift's end: found
        empty meanwhile, the arm is stopped at once and the check fails. A check still waiting when
        the motion has been handed over stays for the next one."""
        check = self._lift_check
        if check is None:
            return await motion
        move = asyncio.ensure_future(motion)
        try:
            pending: set[asyncio.Future[Any]] = {move, check}
            await asyncio.wait(pending, return_when=asyncio.FIRST_COMPLETED)
        except BaseException:
            move.cancel()
            raise
        if check.done():
            empty = self._lift_check_empty(check)
            self._drop_lift_check()
            if empty:
                # stopped whether the motion is still being handed over or flows on from what was
                with contextlib.suppress(RobotError):
                    await self.robot.stop()
                with contextlib.suppress(RobotError):  # the motion stopped under it
                    await move
                raise GraspFailureError(LIFT_CHECK_FAILED)
        return await move

    def _settle_lift_check(self) -> None:
        """The arm at rest past the lift: a check that saw it empty fails now; one that never saw the arm
        pass (its stream began late) is dropped, and the check that follows reads the sensor."""
        check = self._lift_check
        empty = check is not None and check.done() and self._lift_check_empty(check)
        self._drop_lift_check()
        if empty:
            raise GraspFailureError(LIFT_CHECK_FAILED)

    def _drop_lift_check(self) -> None:
        check, self._lift_check = self._lift_check, None
        if check is not None:
            check.cancel()
            if check.done() and not check.cancelled():
                check.exception()  # retrieved: a failure of a check no longer asked is not an error

    @staticmethod
    def _lift_check_empty(check: asyncio.Future[bool | None]) -> bool:
        if check.cancelled():
            return False
        if (exc := check.exception()) is not None:  # the check that follows reads the sensor instead
            log.warning("the grasp check as the arm passed the lift's end failed: %s", exc)
            return False
        return check.result() is False

    async def _check_holding(self, when: str) -> None:
        holding = await self._arm(self.robot.holding(), self.config.deadlines.gripper_s, "grasp check")
        if holding is False:
            raise GraspFailureError(f"grasp verification {when}: the object is not in the gripper")

    async def _open_ahead(self, planned: PlannedPick, i: int) -> None:
        """Open the jaws for the waypoints from ``i`` on that the arm passes without stopping (the
        motion to them ends in motion), before it sets off: an open there needs no stop."""
        plan = planned.plan
        for k in range(i, len(plan.waypoints)):
            traj = planned.trajs[k]
            if traj is None or not traj.ends_in_motion:
                return
            if plan.waypoints[k].gripper is GripperCommand.OPEN:
                w = plan.waypoints[k]
                await self._arm(
                    self.robot.gripper(False), self.config.deadlines.gripper_s, f"gripper {w.gripper}"
                )

    async def _go_home(self) -> None:
        """INIT: a cycle starts at the safe home, out of the camera's view of the table (after an
        aborted cycle or a restart the arm may be anywhere)."""
        if self.config.home_joints is None:
            return
        home = np.asarray(self.config.home_joints, dtype=float)
        q = await self.robot.joints()
        if near(q, home) or self._planning.clear(q):
            return
        # straight up first: nothing is known of the table yet, and an aborted cycle can leave the jaws
        # beside a box (sorting cubes: the joint move home swept through the wall, alarm 117, and the
        # next two trials were lost the same way)
        rise = self.config.home_rise_to_m - float((await self.motion.tool_pose(q))[2, 3])
        try:
            await self._up_then_home(q, rise, home, (), "RISE", "the way to safe home")
        except PlanningError as exc:
            if rise <= 0.0:
                raise
            log.info("no straight way up before going home (%s): straight home", exc)
            await self._up_then_home(q, 0.0, home, (), "RISE", "the way to safe home")

    async def _return_home(self, planned: PlannedPick, obs: Observation) -> None:
        """DONE: out of the camera's view of the table — where the plan's way home ended, or back to
        the safe home when the arm is elsewhere (a touch-down cut short, a resumed plan)."""
        home = planned.home
        if home is None:
            return
        # what was placed is now an obstacle too (the rod standing where the plan put it)
        obstacles = (*obs.obstacles, placed_box(planned.plan))
        try:
            q = await self.robot.joints()
            if near(q, home) or self._planning.clear(q):
                return
            traj = await self._timed(
                self._planning.single(q, Move(MotionKind.JOINT, home, label="HOME"), obstacles),
                self.config.deadlines.plan_s,
                "planning the way home",
            )
            if traj is not None:
                await self._arm(self.robot.execute(traj), self.config.deadlines.motion_s, "returning home")
        except SafetyError:
            raise
        except RobotError as exc:  # the object is placed; a failed way home is reported, not fatal
            log.warning("could not return to safe home after placing: %s", exc)

    # ------------------------------------------------------------------ recovery helpers
    async def _back_off_open(self, planned: PlannedPick) -> None:
        """After a failed grasp: open, back away upward and go on to the safe home, out of the camera's
        view of the table, before looking again (an arm over the table hides the rod it let go of)."""
        await self.robot.gripper(False)
        q = await self.robot.joints()
        try:
            await self._up_then_home(
                q, BACK_OFF_M, planned.home, planned.obstacles, "BACK_OFF", "backing off"
            )
        except RobotError as exc:
            log.warning("could not back off after a failed grasp: %s", exc)

    async def _up_then_home(
        self,
        q: np.ndarray,
        rise_m: float,
        home: np.ndarray | None,
        obstacles: tuple[SeenBox, ...],
        label: str,
        what: str,
    ) -> None:
        """Straight up by ``rise_m`` (none when ≤ 0), flowing on into the joint move to ``home`` (if any),
        planned in one request and executed under the cycle's deadlines."""
        moves: list[Move] = []
        if rise_m > 0.0:
            up = raised(await self.motion.tool_pose(q), rise_m)
            moves.append(Move(MotionKind.LINEAR, up, label=label, blend=home is not None))
        if home is not None:
            moves.append(Move(MotionKind.JOINT, home, label="SAFE_HOME"))
        if not moves:
            return
        cfg = self.config.deadlines
        trajs = await self._timed(self.motion.plan_moves(q, moves, obstacles), cfg.plan_s, f"planning {what}")
        for k, traj in enumerate(trajs):
            if traj is not None:
                flows = k + 1 < len(trajs) and traj.ends_in_motion
                await self._arm(self.robot.execute(traj, continues=flows), cfg.motion_s, what)

    async def _leave_safe(self, release: bool = False) -> None:
        """Before giving up: stop whatever moves; the arm stays where it is, enabled and idle (with its
        jaws open when ``release``)."""
        try:
            await self.robot.stop()
        except RobotError as exc:
            log.warning("stop while aborting failed: %s", exc)
        if release:
            try:
                await self._arm(self.robot.gripper(False), self.config.deadlines.gripper_s, "gripper open")
            except RobotError as exc:
                log.warning("opening the gripper while aborting failed: %s", exc)
