"""The task's cycle loop: :class:`TaskRunner` runs cycles of the :class:`Orchestrator` on request, keeps
counters and status, publishes status on every state change, each pick's record (a PickEvent when its
cycle starts and at each stage it reaches, kept in a :class:`CycleJournal` on disk, and one with its
outcome; a cycle a crash cut is published as interrupted when the task comes back) and the plans it
gets from motion, and turns stop / e-stop into immediate robot commands. No gRPC server here: the
service (:mod:`services.task.service`) wires it to one.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Coroutine, Iterator, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from pickplace.v1 import common_pb2, task_pb2

from services.common.bus import Bus
from services.common.errors import InvalidInputError, SafetyError
from services.common.keys import CellKeys
from services.common.modes import TaskKind
from services.common.settings import REPO_ROOT, Settings
from services.common.shell import ShellStateError
from services.kinematics.analytic import fk
from services.kinematics.model import load_arm
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import tool_frame, tool_geometry
from services.kinematics.trajectory import JointTrajectory
from services.task.clients import CellClients, boxes_msg
from services.task.cycle import CycleConfig, Orchestrator
from services.task.journal import CycleJournal, interrupted
from services.task.messages import pick_event_msg
from services.task.ports import MotionPort, Move, SeenBox
from services.task.recovery import RetryLimits
from services.task.states import CycleState, PickOutcome, StateDeadlines, TaskCounters
from services.task.view import CameraModel, ViewCheck

log = logging.getLogger("pickplace.task.runner")

TASKS = tuple(TaskKind)
# states after which the cycle's outcome follows at once: no running record for them
_ENDING = (CycleState.DONE, CycleState.ABORT, CycleState.ESTOP)
# an interrupted cycle found at start goes out again with this many status ticks (a gateway that was
# not listening yet hears it; the database keeps a pick's first outcome, so repeats change nothing)
REPUBLISH_TICKS = 10


def journal_path(settings: Settings) -> Path:
    """The task's record of the cycle in progress, in the cell's state directory."""
    return settings.state.path(settings.cell_id, REPO_ROOT) / "task" / "cycle.pb"


class Spawn(Protocol):
    """Runs a coroutine in the owner's task group (:meth:`ServiceShell.spawn`)."""

    def __call__(self, coro: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None]: ...


def cycle_config(settings: Settings) -> CycleConfig:
    t = settings.task
    home_deg = settings.grasp.safe_home_joints_deg.get(settings.robot.model)
    return CycleConfig(
        limits=RetryLimits(
            detect=t.detect_retries,
            grasp_variants=t.grasp_alternatives,
            alarms=t.alarm_recoveries,
            regrasps=t.regrasps,
        ),
        deadlines=StateDeadlines(
            detect_s=t.detect_deadline_s,
            plan_s=t.plan_deadline_s,
            motion_s=t.motion_deadline_s,
            gripper_s=t.gripper_deadline_s,
        ),
        detect_retry_delay_s=t.detect_retry_delay_s,
        verify_grasp=t.verify_grasp,
        touch_down_extension_m=t.touch_down_extension_m,
        jaw_footprint_m=(settings.motion.tool.finger_box_m[0], settings.motion.tool.finger_box_m[1]),
        jaw_clearance_m=settings.motion.padding_m,
        home_joints=tuple(float(np.deg2rad(v)) for v in home_deg) if home_deg is not None else None,
        max_joint_acceleration=tuple(float(a) for a in get_robot(settings.robot.model).max_acceleration),
        home_rise_to_m=t.home_rise_to_m,
        # as high as the pre-grasp: the plan's first move from there is short
        set_off_height_m=settings.grasp.approach_distance_m if t.set_off_before_planned else 0.0,
        straighten_from_offset_m=t.straighten_from_offset_m,
        straighten_min_deg=t.straighten_min_deg,
        straighten_max_deg=t.straighten_max_deg,
        corner_tolerance_m=t.corner_tolerance_m,
        set_off_flows_on=t.set_off_before_planned and t.set_off_flows_on,
        servo_period_s=settings.robot.servo_period_s,
        table_z_m=settings.grasp.table_z_m,
        # where the task stands the rod (None: where it lay, the grasp service's choice)
        place_xy=settings.grasp.rod.place_xy_m,
        place_region_min=settings.grasp.rod.place_region_min_m,
        place_region_max=settings.grasp.rod.place_region_max_m,
    )


def view_check(settings: Settings) -> ViewCheck | None:
    """The camera-model check of the arm against the camera's view of the pick zone (None when
    ``task.park_out_of_view`` is off: then only the safe home counts as out of view)."""
    t = settings.task
    if not t.park_out_of_view:
        return None
    cam = settings.sim.twin.camera
    zone = settings.sim.twin.scene
    camera = CameraModel.look_at(cam.position_m, cam.look_at_m, cam.fovy_deg, cam.width, cam.height)
    arm = load_arm(settings.robot.model, tool_geometry(settings))
    return ViewCheck(
        arm,
        camera,
        zone.pick_zone_min_m,
        zone.pick_zone_max_m,
        t.view_zone_height_m,
        settings.grasp.table_z_m,
        t.view_margin_px,
        settings.vision.cubes.max_height_m,  # vision sees what stands this high on the table ...
        settings.vision.cubes.robot_base_radius_m,  # ... but for the robot's own base
    )


class PublishedPlans:
    """The motion port of the cycle, publishing every plan it hands out (``TaskPlan`` on ``keys.task_plans``:
    the tool tip's path and the boxes planned around) for the live view and the recorder. A plan that
    cannot be published is logged; the cycle goes on with it."""

    def __init__(self, motion: MotionPort, settings: Settings, publish: Callable[[task_pb2.TaskPlan], None]):
        self.motion = motion
        self.publish = publish
        self.cycle_index = 0  # set by the runner at each cycle
        self._spec = get_robot(settings.robot.model)
        self._T_flange_tool = tool_frame(settings)
        self._seq = 0

    async def tool_pose(self, q: np.ndarray) -> np.ndarray:
        return await self.motion.tool_pose(q)

    async def plan_moves(
        self,
        start: np.ndarray,
        moves: Sequence[Move],
        obstacles: tuple[SeenBox, ...],
        start_velocity: np.ndarray | None = None,
    ) -> list[JointTrajectory | None]:
        planned = await self.motion.plan_moves(start, moves, obstacles, start_velocity)
        try:
            self.publish(self.message(planned, moves, obstacles))
        except Exception:  # the view of a plan must never fail the cycle: logged, the plan goes on
            log.warning("publishing a plan failed", exc_info=True)
        return planned

    def message(
        self, planned: Sequence[JointTrajectory | None], moves: Sequence[Move], obstacles: tuple[SeenBox, ...]
    ) -> task_pb2.TaskPlan:
        self._seq += 1
        boxes: dict[tuple[float, ...], SeenBox] = {}  # the plan's boxes and each move's own, once each
        for b in (*obstacles, *(b for m in moves for b in m.obstacles)):
            boxes.setdefault((*np.ravel(b.min), *np.ravel(b.max)), b)
        knots = [t.positions for t in planned if t is not None]
        xyz = (
            fk(self._spec, np.concatenate(knots), self._T_flange_tool)[:, :3, 3]
            if knots
            else np.zeros((0, 3))
        )
        return task_pb2.TaskPlan(
            header=common_pb2.Header(stamp_ns=time.time_ns(), frame_id="base", seq=self._seq),
            cycle_index=self.cycle_index,
            label="+".join(m.label for m in moves if m.label),
            tool_path=[common_pb2.Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in xyz],
            boxes=boxes_msg(tuple(boxes.values())),
        )


class TaskRunner:
    """Runs cycles, tracks counters and status, and reports every outcome."""

    def __init__(
        self,
        settings: Settings,
        clients: CellClients,
        bus: Bus | None = None,
        between_cycles: Callable[[], object] | None = None,
        spawn: Spawn | None = None,
        clock: Callable[[], float] = time.perf_counter,
        journal: CycleJournal | None = None,
    ):
        self.settings = settings
        self.clients = clients
        self.bus = bus
        self.keys = CellKeys(settings.cell_id)
        self.counters = TaskCounters()
        self.task = settings.task.task
        self.state = CycleState.IDLE
        self.message = ""
        self.last_error = ""
        self.cycle_index = 0
        self.outcomes: list[PickOutcome] = []
        self.listeners: list[Callable[[PickOutcome], None]] = []
        self.between_cycles = between_cycles  # e.g. lay a new rod in the twin
        self._status_queues: set[asyncio.Queue[task_pb2.TaskStatus]] = set()
        self._spawn = spawn  # the task service's task group runs the cycle loop
        self._loop_task: asyncio.Task[None] | None = None
        self._seq = 0
        self.journal = journal or CycleJournal(None)
        self._recording: PickOutcome | None = None  # the cycle whose record this runner keeps
        self._recorded_stage = ""
        # interrupted cycles found at start: published then, with the next status ticks, and again
        # before the next cycle starts
        self.pending_records: list[task_pb2.PickEvent] = []
        self._republish = 0
        self.plans = (  # every plan out on the bus too, for the live view and the recorder
            PublishedPlans(clients.motion, settings, lambda m: bus.publish(self.keys.task_plans, m))
            if bus is not None
            else None
        )
        self.orchestrator = Orchestrator(
            clients.vision,
            clients.grasp,
            self.plans or clients.motion,
            clients.robot,
            cycle_config(settings),
            on_state=self._on_state,
            clock=clock,
            view=view_check(settings),
        )

    # ------------------------------------------------------------------ status
    @property
    def running(self) -> bool:
        return self._loop_task is not None and not self._loop_task.done()

    def status(self) -> task_pb2.TaskStatus:
        from services.task.states import ACTIVE_STATES, PROGRESS

        self._seq += 1
        return task_pb2.TaskStatus(
            header=common_pb2.Header(stamp_ns=time.time_ns(), frame_id="base", seq=self._seq),
            state=self.state.value,
            message=self.message,
            progress=PROGRESS.get(self.state, 0.0),
            picks_completed=self.counters.picks_completed,
            picks_failed=self.counters.picks_failed,
            average_cycle_time=self.counters.average_cycle_time,
            task=self.task,
            running=self.running,
            cycle_index=self.cycle_index,
            last_error=self.last_error,
            cycle_active=self.running or self.state in ACTIVE_STATES,
        )

    def publish_status(self) -> None:
        msg = self.status()
        if self.bus is not None:
            try:
                self.bus.publish(self.keys.task_status, msg)
            except Exception as exc:
                log.warning("publishing task status failed: %s", exc)
        for q in list(self._status_queues):
            if q.full():
                q.get_nowait()
            q.put_nowait(msg)

    def _on_state(self, state: CycleState, message: str) -> None:
        self.state = state
        self.message = message
        self._record_progress(state)
        self.publish_status()

    # ------------------------------------------------------------------ pick records
    def publish_record(self, event: task_pb2.PickEvent) -> None:
        """A running record on ``pick_progress``, an outcome (once per pick, but for a repeated
        interrupted one) on ``pick_events``."""
        if self.bus is None:
            return
        running = event.status == task_pb2.PICK_STATUS_RUNNING
        try:
            self.bus.publish(self.keys.pick_progress if running else self.keys.pick_events, event)
        except Exception as exc:
            log.warning("publishing pick event failed: %s", exc)

    def recover_records(self) -> task_pb2.PickEvent | None:
        """At start: a cycle the last task process left unfinished is published as interrupted."""
        event = self.journal.leftover()
        if event is None:
            return None
        log.warning(
            "cycle %s was cut at %s when the last task process ended: recorded as interrupted",
            event.pick_id,
            event.stage_reached,
        )
        self.pending_records.append(event)
        self.publish_record(event)
        self._republish = REPUBLISH_TICKS
        return event

    def republish_pending(self) -> None:
        """With a status tick: the interrupted cycles found at start, once more (a bounded number of times)."""
        if self._republish <= 0:
            return
        self._republish -= 1
        for event in self.pending_records:
            self.publish_record(event)

    def _record_progress(self, state: CycleState) -> None:
        """The cycle's running record: when it starts and at each stage it reaches (on disk and out)."""
        current = self.orchestrator.current
        if current is None:
            return
        if current is not self._recording:  # a new cycle starts
            self._recording, self._recorded_stage = current, ""
            pending, self.pending_records = self.pending_records, []
            for event in pending:  # before this cycle's row, in case nobody heard them at start
                self.publish_record(event)
        if state in _ENDING or current.stage_reached == self._recorded_stage:
            return
        self._recorded_stage = current.stage_reached
        event = pick_event_msg(current, self.settings.cell_id, task_pb2.PICK_STATUS_RUNNING)
        self.journal.write(event)
        self.publish_record(event)

    def _record_cut(self, exc: BaseException) -> None:
        """The cycle ended without an outcome of its own (a safety stop, a lost service, the operator's
        stop, a bug): its record says so."""
        out, self._recording = self._recording, None
        if out is None:
            return
        event = pick_event_msg(out, self.settings.cell_id)
        if isinstance(exc, asyncio.CancelledError):
            event = interrupted(event, "stopped (the operator's stop or a shutdown)")
        elif not out.failure_reason:
            event.failure_reason = f"{out.stage_reached}: {type(exc).__name__}: {exc}"
            event.error_code = type(exc).__name__
        self.publish_record(event)
        self.journal.clear()

    @contextlib.contextmanager
    def status_subscription(self) -> Iterator[asyncio.Queue[task_pb2.TaskStatus]]:
        q: asyncio.Queue[task_pb2.TaskStatus] = asyncio.Queue(64)
        self._status_queues.add(q)
        try:
            yield q
        finally:
            self._status_queues.discard(q)

    # ------------------------------------------------------------------ cycles
    async def run_cycle(self, task: str | None = None) -> PickOutcome:
        task = task or self.task
        if task not in TASKS:
            raise InvalidInputError(f"unknown task {task!r}; choose one of {[str(t) for t in TASKS]}")
        self.task = TaskKind(task)
        self.cycle_index += 1
        if self.plans is not None:
            self.plans.cycle_index = self.cycle_index
        self._recording = None
        try:
            outcome = await self.orchestrator.run(task)
        except BaseException as exc:
            self._record_cut(exc)
            raise
        self._report(outcome)
        return outcome

    def _report(self, outcome: PickOutcome) -> None:
        self.counters.record(outcome)
        self.outcomes.append(outcome)
        if not outcome.success:
            self.last_error = outcome.failure_reason
        self._recording = None
        self.publish_record(pick_event_msg(outcome, self.settings.cell_id))
        self.journal.clear()
        for cb in list(self.listeners):
            cb(outcome)
        self.publish_status()

    async def _loop(self, cycles: int) -> None:
        n = 0
        try:
            while cycles == 0 or n < cycles:
                n += 1
                try:
                    await self.run_cycle()
                except SafetyError as exc:
                    self.last_error = str(exc)
                    self._on_state(CycleState.ESTOP, f"safety stop: {exc}; waiting for the operator")
                    return
                if cycles and n >= cycles:
                    break
                if self.between_cycles is not None:
                    await self._between_cycles()
                await asyncio.sleep(self.settings.task.pause_between_cycles_s)
            self._on_state(CycleState.IDLE, f"finished {n} cycle(s)")
        except asyncio.CancelledError:
            self._on_state(CycleState.STOPPED, "stopped by the operator")
            raise
        except Exception as exc:  # the loop's boundary: a bug ends the loop, not the service; say so
            log.exception("task loop failed")
            self.last_error = f"{type(exc).__name__}: {exc}"
            self._on_state(CycleState.IDLE, f"task loop failed: {self.last_error}")

    async def _between_cycles(self) -> None:
        """Run the between-cycles hook (a new twin scene, say); its failure is reported and the loop goes
        on with the cell as it is: one bad scene never ends the cell."""
        assert self.between_cycles is not None
        try:
            res = self.between_cycles()
            if asyncio.iscoroutine(res):
                await res
        except Exception as exc:
            log.warning(
                "between cycles: %s: %s; the next cycle runs in the current scene", type(exc).__name__, exc
            )
            self.last_error = f"between cycles: {type(exc).__name__}: {exc}"

    def start(self, task: str | None = None, cycles: int = 0) -> None:
        if self.running:
            raise InvalidInputError("the task is already running; stop it first")
        if task:
            if task not in TASKS:
                raise InvalidInputError(f"unknown task {task!r}; choose one of {[str(t) for t in TASKS]}")
            self.task = TaskKind(task)
        if self._spawn is None:
            raise ShellStateError("the task runner runs cycles only inside a running task service")
        self._loop_task = self._spawn(self._loop(cycles), "loop")

    async def wait(self) -> None:
        if self._loop_task is not None:
            with contextlib.suppress(asyncio.CancelledError):
                await self._loop_task

    async def cancel_loop(self) -> None:
        """End the cycle loop (if it runs) and wait until it has reported STOPPED."""
        task, self._loop_task = self._loop_task, None
        if task is not None and not task.done():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def stop(self) -> None:
        """Stop the loop and the arm now (the current cycle is abandoned, the arm held)."""
        await self.cancel_loop()
        await self.clients.robot.stop()

    async def emergency_stop(self) -> None:
        """E-stop first, bookkeeping after."""
        try:
            await self.clients.robot.emergency_stop()
        finally:
            await self.cancel_loop()
            self.last_error = "emergency stop"
            self._on_state(CycleState.ESTOP, "emergency stop pressed; release, clear and start again")
