"""Scripted fakes of the orchestrator's ports (services/task/ports.py), in process, on a fake clock.

A toy arm keeps them consistent: joint positions q map to the tool pose with translation q[:3] and
no rotation, so a joint goal and a tool pose name the same place. The fake robot records every
command it receives, its clock advances by the duration of what it executes, and it can be
scripted to raise an alarm or a safety stop in the middle of a given move.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from services.common.errors import ObjectNotDetectedError
from services.common.modes import GripperCommand, MotionKind, TaskKind
from services.kinematics.trajectory import JointTrajectory
from services.task.cycle import CycleConfig, Orchestrator
from services.task.ports import (
    GraspPlan,
    GripOutcome,
    HeldRodQuery,
    Move,
    MoveOutcome,
    Observation,
    PlannedWaypoint,
    SeenAxis,
    SeenBox,
    SeenCube,
    SeenRod,
)
from services.task.recovery import RetryLimits
from services.task.states import CycleState, PickOutcome

NAMES = tuple(f"joint{k}" for k in range(1, 7))
HOME = np.array([0.3, 0.0, 0.4, 0.0, 0.0, 0.0])
SPEED_RAD_S = 0.5  # the toy arm's joint speed
HELD_ROD = object()  # stands for motion's AttachedObject message


def joints_at(p: Sequence[float]) -> np.ndarray:
    return np.array([*p, 0.0, 0.0, 0.0], dtype=float)


def tool_pose_of(q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = q[:3]
    return T


def line(a: np.ndarray, b: np.ndarray, label: str = "") -> JointTrajectory:
    """A two-point trajectory from a to b at the toy arm's speed; ``label`` rides in its meta."""
    duration = max(float(np.max(np.abs(b - a))) / SPEED_RAD_S, 0.01)
    z = np.zeros((2, len(NAMES)))
    return JointTrajectory(NAMES, np.array([0.0, duration]), np.vstack([a, b]), z, z.copy(), {"label": label})


def rod_at(x: float, y: float, length: float = 0.2) -> SeenRod:
    return SeenRod(np.array([x, y, 0.011]), np.array([1.0, 0.0, 0.0]), length, 0.022, 0.9)


def seen(*rods: SeenRod, cubes: tuple[SeenCube, ...] = (), notes: tuple[str, ...] = ()) -> Observation:
    return Observation(rods=rods, cubes=cubes, notes=notes)


class FakeVision:
    """Answers each observe() with the next scripted observation (or raises the scripted error);
    the last entry repeats. A held rod's axis: the next of ``held`` (none scripted: not seen)."""

    def __init__(self, *script: Observation | Exception, held: tuple[SeenAxis | Exception, ...] = ()):
        self.script = list(script)
        self.calls = 0
        self.held = list(held)
        self.held_queries: list[HeldRodQuery] = []

    async def observe(self) -> Observation:
        item = self.script[min(self.calls, len(self.script) - 1)]
        self.calls += 1
        if isinstance(item, Exception):
            raise item
        return item

    async def held_rod_axis(self, query: HeldRodQuery) -> SeenAxis:
        self.held_queries.append(query)
        if not self.held:
            raise ObjectNotDetectedError("held rod: none scripted")
        item = self.held[min(len(self.held_queries), len(self.held)) - 1]
        if isinstance(item, Exception):
            raise item
        return item


@dataclass
class GraspCall:
    target: str
    alternative: int
    grasp_offset_m: float | None
    q_now: tuple[float, ...]
    target_z: float | None = None  # how high the object to pick was taken to lie
    other_branches: bool = False


def _wp(name: str, kind: MotionKind, p: Sequence[float], **kw: object) -> PlannedWaypoint:
    q = joints_at(p)
    return PlannedWaypoint(name, kind, tool_pose_of(q), q, **kw)  # type: ignore[arg-type]


GUARD = {
    "guard_force_n": 0.6,
    "guard_overtravel_m": 0.02,
    "guard_speed_m_s": 0.02,
    "guard_direction": np.array([0.0, 0.0, -1.0]),
}


class FakeGrasp:
    """Plans the seed's waypoint sequence around the target (toy poses); ``failures`` maps a call
    number (0 = the first) to the error that call raises."""

    def __init__(self, failures: dict[int, Exception] | None = None, cube_drop: bool = False):
        self.failures = dict(failures or {})
        self.cube_drop = cube_drop  # cubes are dropped (grasp.cubes.release: drop): no guarded touch-down
        self.calls: list[GraspCall] = []
        self.plans: list[GraspPlan] = []

    def _record(self, call: GraspCall) -> None:
        k = len(self.calls)
        self.calls.append(call)
        if k in self.failures:
            raise self.failures[k]

    async def plan_rod(
        self,
        rod: SeenRod,
        q_now: np.ndarray,
        obstacles: tuple[SeenBox, ...],
        alternative: int,
        place_xy: np.ndarray | None = None,
        grasp_offset_m: float | None = None,
        other_branches: bool = False,
    ) -> GraspPlan:
        self._record(
            GraspCall("rod", alternative, grasp_offset_m, tuple(q_now), float(rod.center[2]), other_branches)
        )
        x, y = rod.center[0] + (grasp_offset_m or 0.0), rod.center[1]
        px, py = (0.45, 0.0) if place_xy is None else map(float, place_xy)
        waypoints = [
            _wp("SAFE_HOME", MotionKind.JOINT, HOME[:3]),
            _wp("PRE_GRASP", MotionKind.JOINT, (x, y, 0.10), gripper=GripperCommand.OPEN),
            _wp("GRASP", MotionKind.LINEAR, (x, y, 0.02), gripper=GripperCommand.CLOSE),
            _wp("LIFT", MotionKind.LINEAR, (x, y, 0.20), holding=True),
            _wp("REORIENT", MotionKind.LINEAR, (px, py, 0.30), holding=True),
            _wp("PLACE", MotionKind.LINEAR, (px, py, 0.12), holding=True, **GUARD),
            _wp("RELEASE", MotionKind.HOLD, (px, py, 0.12), gripper=GripperCommand.OPEN, holding=True),
            _wp("RETRACT", MotionKind.LINEAR, (px, py, 0.25)),
        ]
        self.plans.append(GraspPlan(TaskKind.STAND_ROD, waypoints, 0.8, HELD_ROD, np.array([px, py, 0.0])))
        return self.plans[-1]

    async def plan_cube(
        self, cube: SeenCube, q_now: np.ndarray, obstacles: tuple[SeenBox, ...], alternative: int
    ) -> GraspPlan:
        self._record(GraspCall(f"cube_{cube.color}", alternative, None, tuple(q_now)))
        x, y = cube.centroid[:2]
        waypoints = [
            _wp("SAFE_HOME", MotionKind.JOINT, HOME[:3]),
            _wp("PRE_GRASP", MotionKind.JOINT, (x, y, 0.10), gripper=GripperCommand.OPEN),
            _wp("GRASP", MotionKind.LINEAR, (x, y, 0.025), gripper=GripperCommand.CLOSE),
            _wp("LIFT", MotionKind.LINEAR, (x, y, 0.15), holding=True),
            _wp("TRANSPORT", MotionKind.JOINT, (0.3, -0.45, 0.15), holding=True),
            _wp(
                "PLACE",
                MotionKind.LINEAR,
                (0.3, -0.45, 0.03),
                holding=True,
                **({} if self.cube_drop else GUARD),
            ),
            _wp("RELEASE", MotionKind.HOLD, (0.3, -0.45, 0.03), gripper=GripperCommand.OPEN, holding=True),
            _wp("RETRACT", MotionKind.LINEAR, (0.3, -0.45, 0.15)),
        ]
        self.plans.append(GraspPlan(TaskKind.SORT_CUBES, waypoints, 0.7, None, np.array([0.3, -0.45, 0.0])))
        return self.plans[-1]


@dataclass
class MotionRequest:
    start: tuple[float, ...]
    moves: list[Move]
    obstacles: tuple[SeenBox, ...]
    start_velocity: tuple[float, ...] | None = None  # the arm moving at the start

    @property
    def labels(self) -> list[str]:
        return [m.label for m in self.moves]


class FakeMotion:
    """Straight joint lines on the toy arm; ``failures`` maps a request number to the error it raises."""

    def __init__(self, failures: dict[int, Exception] | None = None, blending: bool = False):
        self.failures = dict(failures or {})
        self.requests: list[MotionRequest] = []
        self.blending = blending  # a move marked ``blend`` ends in motion (as the motion service cuts it)

    def labelled(self, labels: list[str]) -> MotionRequest:
        """The one request for exactly these moves."""
        (found,) = [r for r in self.requests if r.labels == labels]
        return found

    async def plan_moves(
        self,
        start: np.ndarray,
        moves: Sequence[Move],
        obstacles: tuple[SeenBox, ...],
        start_velocity: np.ndarray | None = None,
    ) -> list[JointTrajectory | None]:
        k = len(self.requests)
        v0 = None if start_velocity is None else tuple(float(v) for v in start_velocity)
        self.requests.append(MotionRequest(tuple(start), list(moves), obstacles, v0))
        if k in self.failures:
            raise self.failures[k]
        out: list[JointTrajectory | None] = []
        q = np.asarray(start, dtype=float)
        for m in moves:
            goal = joints_at(m.target[:3, 3]) if m.target.shape == (4, 4) else m.target  # a tool pose
            if m.kind is MotionKind.JOINT and np.max(np.abs(goal - q)) < 1e-9:
                out.append(None)  # already there
                continue
            traj = line(q, goal, m.label)
            if v0 is not None and not out:  # from the arm's motion: it starts as fast as the arm moves
                traj.velocities[0] = v0
            if self.blending and m.blend:
                traj.velocities[-1] = (goal - q) / traj.duration
            out.append(traj)
            q = goal
        return out

    async def tool_pose(self, q: np.ndarray) -> np.ndarray:
        return tool_pose_of(q)


@dataclass
class Fault:
    """Raised in the middle of a move: the arm stops ``at`` of the way there."""

    error: Exception
    at: float = 0.5
    safety: bool = False  # a safety stop: the controller stays stopped until the operator releases it


@dataclass
class FakeRobot:
    """Records commands as tuples: ("recover",), ("move", label, guarded), ("gripper", "open"|"close"),
    ("stop",); ``label`` is the move's label (the fake motion puts it in the trajectory's meta).
    ``faults`` maps a move number (0 = the first move) to the fault raised during it; ``holding_script``
    scripts the object sensor's answers (the last repeats); guarded moves touch down ``touch_at`` of
    the way, or each the next of ``touch_script`` (the last repeats; 1.0: no touch-down on the way)."""

    q: np.ndarray = field(default_factory=lambda: HOME.copy())
    faults: dict[int, Fault] = field(default_factory=dict)
    holding_script: list[bool] = field(default_factory=lambda: [True])
    touch_at: float = 0.75
    touch_script: list[float] = field(default_factory=list)
    commands: list[tuple[object, ...]] = field(default_factory=list)
    releases: list[bool] = field(default_factory=list)  # per gripper command: sent as a release
    clock_s: float = 0.0  # the controller's clock: advances by what the arm executes
    moves: int = 0
    continued: list[str] = field(default_factory=list)  # labels of the moves sent as continuing
    reached: dict[str, np.ndarray] = field(default_factory=dict)  # where each labelled move left the arm
    safety_stopped: bool = False
    passings: list[np.ndarray] = field(default_factory=list)  # poses a grasp check waited to pass
    passing_after: int = 0
    _moved: asyncio.Event = field(default_factory=asyncio.Event)
    holding_reads: list[int] = field(default_factory=list)  # per object-sensor read: commands sent before it
    _holding_calls: int = 0
    _guarded_calls: int = 0

    async def joints(self) -> np.ndarray:
        return self.q.copy()

    async def execute(
        self, traj: JointTrajectory, force_guard_n: float = 0.0, continues: bool = False
    ) -> MoveOutcome:
        from services.common.errors import EmergencyStopError

        if self.safety_stopped:
            raise EmergencyStopError("the emergency stop is pressed")
        k = self.moves
        self.moves += 1
        a, b = traj.positions[0], traj.positions[-1]
        fault = self.faults.get(k)
        share = fault.at if fault else (self._touch_share() if force_guard_n > 0 else 1.0)
        self.q = a + share * (b - a)
        self.clock_s += share * traj.duration
        self.commands.append(("move", traj.meta.get("label", ""), force_guard_n > 0))
        self.reached[str(traj.meta.get("label", ""))] = self.q.copy()
        self._moved.set()
        if continues:
            self.continued.append(str(traj.meta.get("label", "")))
        if fault is not None:
            self.safety_stopped = fault.safety
            raise fault.error
        return MoveOutcome(self.q.copy(), share * traj.duration, stopped_early=share < 1.0)

    def _touch_share(self) -> float:
        if not self.touch_script:
            return self.touch_at
        share = self.touch_script[min(self._guarded_calls, len(self.touch_script) - 1)]
        self._guarded_calls += 1
        return share

    async def gripper(self, close: bool, release: bool = False) -> GripOutcome:
        self.commands.append(("gripper", GripperCommand.CLOSE if close else GripperCommand.OPEN))
        self.releases.append(release)
        return GripOutcome(closed=close, object_detected=None)

    async def holding(self) -> bool | None:
        answer = self.holding_script[min(self._holding_calls, len(self.holding_script) - 1)]
        self._holding_calls += 1
        self.holding_reads.append(len(self.commands))
        return answer

    async def holding_on_passing(self, q: np.ndarray) -> bool | None:
        """The next scripted answer, once the arm has gone on by ``passing_after`` moves (the toy arm
        executes each move at once: what was queued after the pose is the way past it)."""
        self.passings.append(q.copy())
        until = self.moves + self.passing_after
        while self.moves < until:
            self._moved.clear()
            await self._moved.wait()
        return await self.holding()

    async def recover(self) -> None:
        from services.common.errors import EmergencyStopError

        self.commands.append(("recover",))
        if self.safety_stopped:
            raise EmergencyStopError("the emergency stop is pressed; release it before starting")

    async def stop(self) -> None:
        self.commands.append(("stop",))

    async def emergency_stop(self) -> None:
        self.commands.append(("emergency_stop",))
        self.safety_stopped = True


class WaitRecorder:
    """Stands in for asyncio.sleep: records what the orchestrator asked to wait, returns at once."""

    def __init__(self) -> None:
        self.waits: list[float] = []

    async def __call__(self, seconds: float) -> None:
        self.waits.append(seconds)


@dataclass
class FakeView:
    """The arm against the camera on the toy arm: the view is clear with the tool at least
    ``clear_above_m`` high; a seen box is the arm when the tool (q[:3]) lies inside it."""

    clear_above_m: float = 0.25
    asked: list[tuple[float, ...]] = field(default_factory=list)

    def clear(self, q: np.ndarray) -> bool:
        self.asked.append(tuple(q))
        return bool(q[2] >= self.clear_above_m - 1e-9)

    def holds_arm(self, q: np.ndarray, box_min: np.ndarray, box_max: np.ndarray) -> bool:
        return bool(np.all(q[:3] >= box_min) and np.all(q[:3] <= box_max))


@dataclass
class FakeCell:
    """The four fakes and an orchestrator over them, its states recorded and its clock the robot's."""

    vision: FakeVision
    grasp: FakeGrasp = field(default_factory=FakeGrasp)
    motion: FakeMotion = field(default_factory=FakeMotion)
    robot: FakeRobot = field(default_factory=FakeRobot)
    config: CycleConfig = field(
        default_factory=lambda: CycleConfig(
            limits=RetryLimits(detect=2, grasp_variants=3, alarms=2, regrasps=1),
            home_joints=tuple(HOME),
            corner_tolerance_m=0.01,
        )
    )
    wait: WaitRecorder = field(default_factory=WaitRecorder)
    view: FakeView | None = None
    states: list[CycleState] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.orchestrator = Orchestrator(
            self.vision,
            self.grasp,
            self.motion,
            self.robot,
            self.config,
            on_state=self._on_state,
            wait=self.wait,
            clock=lambda: self.robot.clock_s,
            view=self.view,
        )

    def _on_state(self, state: CycleState, message: str) -> None:
        self.states.append(state)
        self.messages.append(message)

    async def run(self, task: TaskKind = TaskKind.STAND_ROD) -> PickOutcome:
        return await self.orchestrator.run(task)

    def moves(self) -> list[str]:
        """The labels of the moves the robot was sent, in order."""
        return [str(c[1]) for c in self.robot.commands if c[0] == "move"]
