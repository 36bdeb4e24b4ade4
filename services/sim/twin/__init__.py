"""The physics twin of the cell: MuJoCo Nova5 (or UR5e/UR3) + gripper + rod/cubes + simulated RealSense.

``create_twin_engine(settings, seed)`` gives the ``MotionEngine`` behind the simulated Dobot;
``TwinCamera`` renders aligned RGB-D frames of it; ``ground_truth`` (evaluation only) reads object
poses, contacts and success checks; ``dataset.write_sim_scene`` writes a frame set + ground truth.
"""

from __future__ import annotations

import os

# Off-screen rendering on CPU (Mesa llvmpipe) unless the user chose a GL backend; mujoco reads
# this when it is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

from services.sim.twin.camera import TwinCamera, create_twin_camera
from services.sim.twin.engine import TwinEngine, TwinSnapshot, create_twin_engine
from services.sim.twin.model import TwinWorld, build_world
from services.sim.twin.scene import Scene, SceneObject, sample_scene

__all__ = [
    "Scene",
    "SceneObject",
    "TwinCamera",
    "TwinEngine",
    "TwinSnapshot",
    "TwinWorld",
    "build_world",
    "create_twin_camera",
    "create_twin_engine",
    "sample_scene",
]
