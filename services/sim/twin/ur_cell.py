"""The MuJoCo twin of a UR cell: the same scene, camera and parallel gripper as the Nova5's, built
from the UR5e/UR3 kinematics (``build_world`` reads ``robot.model``), behind the simulated UR
controller (:class:`services.sim.ur.controller.URController`) instead of the simulated Dobot.

The gripper sits on the flange's tool outputs (``gripper.tool_outputs``: UR tool DO 0 closes, DO 1
opens), which the UR controller hands to the twin in its engine convention (tool outputs from bit 32).

:class:`EngineTruth` is what an evaluation asks of a twin's ground truth, in values that cross a
process boundary (the UR twin lives in the simulated controller's own process, see
:mod:`services.sim.ur.process`); the Nova5 cell asks its in-process engine the same questions.
"""

from __future__ import annotations

from collections.abc import Callable

from services.common.settings import Settings
from services.common.settings.robot import RobotDriverKind
from services.sim.twin.engine import TwinEngine, create_twin_engine
from services.sim.twin.ground_truth import CubePlaceResult, RodStandResult
from services.sim.ur.truth import SceneRecord, TruthQuery

UR_MODELS = ("ur5e", "ur3")
# The simulated UR runs in a process of its own: on a machine busy enough to starve it, it can stay
# silent for a second of wall time without any link fault (the in-process Dobot sim stalls with its host)
SIM_FEEDBACK_TIMEOUT_S = 3.0


def ur_cell_settings(settings: Settings, model: str) -> Settings:
    """``settings`` for a simulated UR cell: the model, the UR driver, the gripper on the tool outputs,
    the twin's arm starting at the model's safe home (a Nova5's start pose would put a UR's forearm
    into the table), and at least ``SIM_FEEDBACK_TIMEOUT_S`` of silence before the link counts as lost."""
    if model not in UR_MODELS:
        raise ValueError(f"a UR cell is one of {UR_MODELS}, not {model!r}")
    robot = settings.robot.model_copy(
        update={
            "model": model,
            "driver": RobotDriverKind.UR_RTDE,
            "feedback_timeout_s": max(settings.robot.feedback_timeout_s, SIM_FEEDBACK_TIMEOUT_S),
        }
    )
    gripper = settings.gripper.model_copy(update={"tool_outputs": True, "close_do": 1, "open_do": 2})
    home = settings.grasp.safe_home_joints_deg[model]
    twin = settings.sim.twin.model_copy(update={"initial_joints_deg": tuple(home)})
    sim = settings.sim.model_copy(update={"twin": twin})
    return settings.model_copy(update={"robot": robot, "gripper": gripper, "sim": sim})


def create_ur_twin_engine(settings: Settings, model: str, seed: int | None = None) -> TwinEngine:
    """The twin of the UR cell for ``settings`` (seeded scene); the arm starts at the model's safe home
    (:func:`ur_cell_settings`)."""
    return create_twin_engine(ur_cell_settings(settings, model), seed)


class EngineTruth:
    """Ground truth of the twin engine ``engine()`` returns now (a scene reset swaps it)."""

    def __init__(self, engine: Callable[[], TwinEngine]):
        self._engine = engine

    def rod_standing(self) -> RodStandResult:
        from services.sim.twin import ground_truth as gt

        return gt.check_rod_standing(self._engine())

    def cube_in_zone(self, color: str) -> CubePlaceResult:
        from services.sim.twin import ground_truth as gt

        return gt.check_cube_in_zone(self._engine(), color)

    def object_velocity(self, name: str) -> tuple[float, float]:
        """(m/s, rad/s) of the object ``name``."""
        from services.sim.twin import ground_truth as gt

        return gt.object_velocity(self._engine(), name)

    def object_tilt_deg(self, name: str) -> float:
        from services.sim.twin import ground_truth as gt

        return gt.axis_tilt_deg(gt.object_pose(self._engine(), name))

    def scene_record(self) -> SceneRecord:
        world = self._engine().world
        record = world.variation.record() if world.variation.randomized else {}
        return SceneRecord(world.scene.seed, world.scene.layout_redraws, record)

    def ask(self, query: TruthQuery, *args: str) -> object:
        """One question by name (what the UR sim's pipe carries)."""
        method: Callable[..., object] = getattr(self, TruthQuery(query).value)
        return method(*args)
