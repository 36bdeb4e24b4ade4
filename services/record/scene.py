"""Scenes for Foxglove's 3D panel (pure): what vision found, what motion planned around, the planned path.

Each function returns one ``foxglove.SceneUpdate`` payload that replaces the previous one on its channel.
"""

from __future__ import annotations

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    TextPrimitive,
    Vector3,
)
from pickplace.v1 import common_pb2, motion_pb2, vision_pb2

from services.record.convert import BASE_FRAME, qmul, timestamp

Array = np.ndarray


# ---------------------------------------------------------------------------- detections
LABEL_RGBA: dict[str, tuple[float, float, float, float]] = {
    "red": (0.9, 0.1, 0.1, 0.9),
    "green": (0.1, 0.75, 0.2, 0.9),
    "blue": (0.15, 0.3, 0.95, 0.9),
    "yellow": (0.95, 0.85, 0.1, 0.9),
    "black": (0.1, 0.1, 0.1, 0.9),
}
ROD_RGBA = (0.2, 0.2, 0.25, 0.95)
OBSTACLE_RGBA = (1.0, 0.55, 0.0, 0.35)
TEXT_RGBA = (1.0, 1.0, 1.0, 1.0)
UNKNOWN_RGBA = (0.6, 0.6, 0.6, 0.9)


def _color(rgba: tuple[float, float, float, float]) -> Color:
    return Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _pose(p: common_pb2.Pose, turn_xyzw: Array | None = None) -> Pose:
    q = np.array([p.qx, p.qy, p.qz, p.qw], dtype=float)
    if not np.any(q):
        q = np.array([0.0, 0.0, 0.0, 1.0])
    if turn_xyzw is not None:
        q = qmul(q, turn_xyzw)
    return Pose(
        position=Vector3(x=p.x, y=p.y, z=p.z),
        orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
    )


def _text(x: float, y: float, z: float, text: str) -> TextPrimitive:
    return TextPrimitive(
        pose=Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=0, y=0, z=0, w=1)),
        billboard=True,
        font_size=14.0,
        scale_invariant=True,
        color=_color(TEXT_RGBA),
        text=text,
    )


# a rod's pose has x along its axis; a Foxglove cylinder's axis is its z: turn +90° about y
_ROD_TURN = np.array([0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])


def scene_update(objs: vision_pb2.DetectedObjects, camera_frame: str, cube_size_m: float) -> bytes:
    """One SceneUpdate replacing the previous one: rods as cylinders, cubes as cubes in their colour,
    obstacle boxes translucent, each with a label; in the base frame when calibrated, else the camera's."""
    stamp = timestamp(objs.header.stamp_ns)
    entities = []
    for k, rod in enumerate(objs.rods):
        frame, pose = (BASE_FRAME, rod.pose_base) if rod.has_base else (camera_frame, rod.pose_camera)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=frame,
                id=f"rod{k}",
                cylinders=[
                    CylinderPrimitive(
                        pose=_pose(pose, _ROD_TURN),
                        size=Vector3(x=rod.diameter_m, y=rod.diameter_m, z=rod.length_m),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=_color(ROD_RGBA),
                    )
                ],
                texts=[_text(pose.x, pose.y, pose.z + 0.04, f"rod {rod.confidence:.2f} ({rod.method})")],
            )
        )
    for k, cube in enumerate(objs.cubes):
        frame, pose = (BASE_FRAME, cube.pose_base) if cube.has_base else (camera_frame, cube.pose_camera)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=frame,
                id=f"cube{k}",
                cubes=[
                    CubePrimitive(
                        pose=_pose(pose),
                        size=Vector3(x=cube_size_m, y=cube_size_m, z=cube_size_m),
                        color=_color(LABEL_RGBA.get(cube.color_label, UNKNOWN_RGBA)),
                    )
                ],
                texts=[_text(pose.x, pose.y, pose.z + cube_size_m, f"cube {cube.color_label}")],
            )
        )
    for k, box in enumerate(objs.obstacles):
        frame, b = (BASE_FRAME, box.base) if box.has_base else (camera_frame, box.camera)
        lo = np.array([b.min.x, b.min.y, b.min.z])
        hi = np.array([b.max.x, b.max.y, b.max.z])
        c, size = (lo + hi) / 2, np.abs(hi - lo)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=frame,
                id=f"obstacle{k}",
                cubes=[
                    CubePrimitive(
                        pose=Pose(
                            position=Vector3(x=c[0], y=c[1], z=c[2]),
                            orientation=Quaternion(x=0, y=0, z=0, w=1),
                        ),
                        size=Vector3(x=size[0], y=size[1], z=size[2]),
                        color=_color(OBSTACLE_RGBA),
                    )
                ],
                texts=[_text(c[0], c[1], hi[2] + 0.03, f"obstacle {box.color_label}".strip())],
            )
        )
    deletions = [SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)]
    return SceneUpdate(deletions=deletions, entities=entities).encode()


# ---------------------------------------------------------------------------- plans
PLAN_RGBA = (0.1, 0.9, 0.9, 1.0)
SCENE_BOX_RGBA = (0.95, 0.2, 0.2, 0.3)
TABLE_RGBA = (0.55, 0.45, 0.35, 0.25)
TABLE_SIZE_M = 1.6
TABLE_THICKNESS_M = 0.01


def _identity_pose(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Pose:
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=0, y=0, z=0, w=1))


def plan_line(tool_xyz: Array, stamp_ns: int, label: str = "") -> bytes:
    """The planned tool path (base frame, one point per trajectory knot) as one line strip."""
    pts = np.asarray(tool_xyz, dtype=float).reshape(-1, 3)
    stamp = timestamp(stamp_ns)
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineStrip,
        pose=_identity_pose(),
        thickness=0.004,
        scale_invariant=False,
        points=[Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in pts],
        color=_color(PLAN_RGBA),
    )
    texts = (
        [_text(float(pts[-1][0]), float(pts[-1][1]), float(pts[-1][2]) + 0.03, label)]
        if label and len(pts)
        else []
    )
    entity = SceneEntity(timestamp=stamp, frame_id=BASE_FRAME, id="plan", lines=[line], texts=texts)
    return SceneUpdate(
        deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)], entities=[entity]
    ).encode()


def planning_scene(
    boxes: list[motion_pb2.CollisionBox], table_z_m: float, padding_m: float, stamp_ns: int
) -> bytes:
    """The boxes motion was asked to plan around (with their padding shown in the label) and the table."""
    stamp = timestamp(stamp_ns)
    h = TABLE_THICKNESS_M
    entities = [
        SceneEntity(
            timestamp=stamp,
            frame_id=BASE_FRAME,
            id="table",
            cubes=[
                CubePrimitive(
                    pose=_identity_pose(0.0, 0.0, table_z_m - h / 2),
                    size=Vector3(x=TABLE_SIZE_M, y=TABLE_SIZE_M, z=h),
                    color=_color(TABLE_RGBA),
                )
            ],
        )
    ]
    for b in boxes:
        lo = np.array([b.x_min, b.y_min, b.z_min])
        hi = np.array([b.x_max, b.y_max, b.z_max])
        c, size = (lo + hi) / 2, np.abs(hi - lo)
        entities.append(
            SceneEntity(
                timestamp=stamp,
                frame_id=BASE_FRAME,
                id=f"box:{b.name}",
                cubes=[
                    CubePrimitive(
                        pose=_identity_pose(*map(float, c)),
                        size=Vector3(x=float(size[0]), y=float(size[1]), z=float(size[2])),
                        color=_color(SCENE_BOX_RGBA),
                    )
                ],
                texts=[
                    _text(
                        float(c[0]),
                        float(c[1]),
                        float(hi[2]) + 0.03,
                        f"{b.name} (+{1000 * padding_m:.0f} mm)",
                    )
                ],
            )
        )
    return SceneUpdate(
        deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)], entities=entities
    ).encode()
