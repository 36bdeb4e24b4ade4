"""The compiled cell: MuJoCo model + the indices the engine, camera and ground truth share."""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from services.common.errors import ConfigurationError
from services.common.settings import GripperSettings, Settings, TwinSettings
from services.kinematics.robot_models import RobotSpec, get_robot
from services.kinematics.tool import tool_frame
from services.sim.twin import mjcf
from services.sim.twin.calibration_board import add_calibration_board
from services.sim.twin.randomization import Variation, nominal_variation, variation_for
from services.sim.twin.scene import Scene, sample_scene

Array = np.ndarray

# Configurations whose mass-matrix diagonal sets the arm gains (the arm stretched out is the worst).
_GAIN_POSES = (
    np.zeros(6),
    np.array([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0]),
    np.array([0.0, np.pi / 2, 0.0, np.pi / 2, np.pi / 2, 0.0]),
)


@dataclass
class TwinWorld:
    """A compiled cell. Read-only after construction; every MjData is made from ``model``."""

    model: mujoco.MjModel
    spec: RobotSpec
    scene: Scene
    twin: TwinSettings
    gripper: GripperSettings
    xml: str
    gains: mjcf.ArmGains
    T_flange_tool: Array  # the cell's one TCP frame (services.kinematics.tool)
    variation: Variation  # what this world is really like (randomization.py; nominal unless randomized)
    arm_qpos: Array = field(init=False)
    arm_dof: Array = field(init=False)
    arm_act: Array = field(init=False)
    grip_act: int = field(init=False)
    finger_qpos: Array = field(init=False)
    finger_dof: Array = field(init=False)
    gripper_body: int = field(init=False)
    flange_site: int = field(init=False)
    tool_site: int = field(init=False)
    ft_site: int = field(init=False)
    force_adr: int = field(init=False)
    torque_adr: int = field(init=False)
    object_body: dict[str, int] = field(init=False)
    object_qpos: dict[str, int] = field(init=False)
    object_dof: dict[str, int] = field(init=False)
    # geom masks (ngeom,)
    robot_geom: Array = field(init=False)  # moving robot geoms (arm links + gripper)
    finger_geom: Array = field(init=False)
    pad_geom: Array = field(init=False)
    env_geom: Array = field(init=False)
    object_geom: Array = field(init=False)
    geom_object: Array = field(init=False)  # geom → index into scene.objects, -1 otherwise

    def __post_init__(self) -> None:
        m = self.model

        def jid(name: str) -> int:
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)

        def bid(name: str) -> int:
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)

        def sid(name: str) -> int:
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)

        arm_j = [jid(n) for n in self.spec.joint_names]
        self.arm_qpos = np.array([m.jnt_qposadr[j] for j in arm_j])
        self.arm_dof = np.array([m.jnt_dofadr[j] for j in arm_j])
        self.arm_act = np.array(
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"act_{n}") for n in self.spec.joint_names]
        )
        self.grip_act = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, mjcf.GRIP_ACTUATOR)
        fj = [jid(n) for n in mjcf.FINGER_JOINTS]
        self.finger_qpos = np.array([m.jnt_qposadr[j] for j in fj])
        self.finger_dof = np.array([m.jnt_dofadr[j] for j in fj])
        self.gripper_body = bid(mjcf.GRIPPER_BODY)
        self.flange_site = sid(mjcf.FLANGE_SITE)
        self.tool_site = sid(mjcf.TOOL_SITE)
        self.ft_site = sid(mjcf.FT_SITE)
        self.force_adr = int(
            m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, mjcf.FORCE_SENSOR)]
        )
        self.torque_adr = int(
            m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, mjcf.TORQUE_SENSOR)]
        )
        self.object_body = {o.name: bid(o.name) for o in self.scene.objects}
        self.object_qpos = {o.name: int(m.jnt_qposadr[jid(f"{o.name}_free")]) for o in self.scene.objects}
        self.object_dof = {o.name: int(m.jnt_dofadr[jid(f"{o.name}_free")]) for o in self.scene.objects}

        robot_bodies = {bid(n) for n in mjcf.ARM_BODIES} | {self.gripper_body}
        finger_bodies = {bid(f"finger_{s}") for s in ("left", "right")}
        robot_bodies |= finger_bodies
        body = m.geom_bodyid
        self.robot_geom = np.isin(body, list(robot_bodies))
        self.finger_geom = np.isin(body, list(finger_bodies))
        self.pad_geom = np.array([m.geom(i).name in mjcf.PAD_GEOMS for i in range(m.ngeom)])
        env_names = {mjcf.TABLE_GEOM} | ({self.scene.obstacle.name} if self.scene.obstacle else set())
        self.env_geom = np.array([m.geom(i).name in env_names for i in range(m.ngeom)])
        obj_index = {b: k for k, b in enumerate(self.object_body[o.name] for o in self.scene.objects)}
        self.geom_object = np.array([obj_index.get(int(b), -1) for b in body])
        self.object_geom = self.geom_object >= 0

    def geom_name(self, g: int) -> str:
        return self.model.geom(int(g)).name or f"geom{g}"

    @property
    def tcp_offset_m(self) -> float:
        return self.gripper.tcp_offset_m

    @property
    def stroke_m(self) -> float:
        return self.gripper.stroke_m


def _compile(xml: str) -> mujoco.MjModel:
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:  # MuJoCo reports XML/compile errors as ValueError
        raise ConfigurationError(f"the twin's MJCF does not compile: {exc}") from exc


def arm_gains(model: mujoco.MjModel, arm_qpos: Array, arm_dof: Array, bandwidth: float) -> mjcf.ArmGains:
    """Critically damped PD gains from the largest joint-space inertia over a few poses."""
    data = mujoco.MjData(model)
    M = np.zeros((model.nv, model.nv))
    inertia = np.zeros(len(arm_dof))
    for q in _GAIN_POSES:
        data.qpos[arm_qpos] = q
        mujoco.mj_forward(model, data)
        mujoco.mj_fullM(model, data, M)
        inertia = np.maximum(inertia, np.diag(M)[arm_dof])
    kp = inertia * bandwidth**2
    kv = 2.0 * inertia * bandwidth
    return mjcf.ArmGains(kp=tuple(float(v) for v in kp), kv=tuple(float(v) for v in kv))


def build_world(
    settings: Settings,
    seed: int | None = None,
    scene: Scene | None = None,
    variation: Variation | None = None,
) -> TwinWorld:
    """Compile the cell for the configured robot and a seeded (or given) scene.

    With ``sim.twin.randomization.enabled`` the world is the seed's :class:`Variation` (rod, frictions,
    table height, grip force, tracking, camera, light), or the given ``variation``; a given ``scene`` keeps
    its own objects (and the nominal world unless a ``variation`` is given too)."""
    twin = settings.sim.twin
    spec = get_robot(settings.robot.model)
    seed = settings.sim.seed if seed is None else seed
    if variation is None:
        variation = variation_for(twin, seed) if scene is None else nominal_variation(twin)
    if scene is None:
        scene = sample_scene(
            variation.scene_settings(twin.scene),
            seed,
            table_z_m=variation.table_height_m,
            rod_friction=variation.rod_table_friction if variation.randomized else None,
        )
    physics = twin.physics.model_copy(
        update={
            "pad_friction": variation.pad_friction,
            "grip_force_n": variation.grip_force_n,
            "tracking_bandwidth_rad_s": variation.tracking_bandwidth_rad_s,
        }
    )
    cam_variation = variation if variation.randomized else None
    args = (spec, settings.gripper, physics, twin.camera, scene)
    draft_xml = mjcf.build_mjcf(*args, variation=cam_variation)
    if twin.calibration_board:  # its mass counts in the gains
        draft_xml = add_calibration_board(draft_xml, settings.vision.calibration.board, settings.gripper)
    draft = _compile(draft_xml)
    names = spec.joint_names
    qadr = np.array(
        [draft.jnt_qposadr[mujoco.mj_name2id(draft, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in names]
    )
    dadr = np.array([draft.jnt_dofadr[mujoco.mj_name2id(draft, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in names])
    gains = arm_gains(draft, qadr, dadr, physics.tracking_bandwidth_rad_s)
    xml = mjcf.build_mjcf(*args, gains=gains, variation=cam_variation)
    if twin.calibration_board:
        xml = add_calibration_board(xml, settings.vision.calibration.board, settings.gripper)
    return TwinWorld(
        model=_compile(xml),
        spec=spec,
        scene=scene,
        twin=twin,
        gripper=settings.gripper,
        xml=xml,
        gains=gains,
        T_flange_tool=tool_frame(settings),
        variation=variation,
    )
