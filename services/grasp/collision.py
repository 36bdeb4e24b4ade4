"""The collision filter of the grasp cores, backed by the motion package's coal checker.

The cores take any ``collision_check(q, held) -> bool``; this adapter answers it with
:class:`services.kinematics.collision.CollisionChecker` — the arm, the gripper, the table and the
obstacle boxes, plus the held object when there is one (one checker per held-object pose,
cached). The held object may touch the table (that is how it is put down; the cores check its
clearance during the carry themselves).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from services.common.settings import Settings
from services.grasp.plan import HeldObject
from services.kinematics.collision import ATTACHED, TABLE, AttachedObject, Box, CollisionChecker, Scene
from services.kinematics.model import ArmModel, load_arm
from services.kinematics.tool import tool_geometry

Array = np.ndarray

MAX_CACHED = 16

__all__ = ["MotionCollisionCheck"]


class MotionCollisionCheck:
    """``collision_check(q, held)`` for one arm and one set of obstacle boxes."""

    def __init__(
        self,
        arm: ArmModel,
        boxes: Sequence[Box] = (),
        table_z: float | None = 0.0,
        padding_m: float = 0.0,
        box_y_extension_m: float = 0.0,
    ):
        self.arm = arm
        self._scene = Scene(
            boxes=tuple(boxes), table_z=table_z, padding_m=padding_m, box_y_extension_m=box_y_extension_m
        )
        self._free = CollisionChecker(arm, self._scene)
        self._held: dict[bytes, CollisionChecker] = {}

    @classmethod
    def from_settings(cls, settings: Settings, boxes: Sequence[Box] = ()) -> MotionCollisionCheck:
        m = settings.motion
        arm = load_arm(settings.robot.model, tool_geometry(settings))
        return cls(arm, boxes, settings.grasp.table_z_m, m.padding_m, m.box_y_extension_m)

    def _checker(self, held: HeldObject | None) -> CollisionChecker:
        if held is None:
            return self._free
        T = np.asarray(held.T_tool_object, dtype=float)
        key = np.round(np.concatenate([T[:3].ravel(), [held.radius, held.length, *held.size]]), 6).tobytes()
        key += held.shape.encode()
        checker = self._held.get(key)
        if checker is None:
            if len(self._held) >= MAX_CACHED:
                self._held.clear()
            attached = AttachedObject(
                shape=held.shape,
                radius=held.radius or 0.011,
                length=held.length or 0.2,
                size=held.size if held.shape == "box" else (0.05, 0.05, 0.05),
                T_tool_object=tuple(tuple(float(v) for v in row) for row in T),
            )
            scene = dataclasses.replace(
                self._scene, attached=attached, allowed=frozenset({(ATTACHED, TABLE)})
            )
            checker = CollisionChecker(self.arm, scene)
            self._held[key] = checker
        return checker

    def __call__(self, q: Array, held: HeldObject | None = None) -> bool:
        return self._checker(held).in_collision(np.asarray(q, dtype=float))

    def with_boxes(self, extra: Sequence[Box]) -> MotionCollisionCheck:
        """The same check with ``extra`` boxes in the scene (what the plan itself puts on the table)."""
        sc = self._scene
        return MotionCollisionCheck(
            self.arm, (*sc.boxes, *extra), sc.table_z, sc.padding_m, sc.box_y_extension_m
        )

    def explain(self, q: Array, held: HeldObject | None = None) -> str:
        return self._checker(held).explain(np.asarray(q, dtype=float))
