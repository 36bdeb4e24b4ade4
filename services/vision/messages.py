"""Conversions between the vision cores' dataclasses and the ``pickplace.v1.vision`` messages."""

from __future__ import annotations

import numpy as np
from pickplace.v1 import common_pb2, vision_pb2

from services.vision.pose import rotation_to_quaternion
from services.vision.results import DetectionResult, Visibility

Array = np.ndarray


def vec3(v: Array) -> vision_pb2.Vec3:
    return vision_pb2.Vec3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def from_vec3(v: vision_pb2.Vec3) -> Array:
    return np.array([v.x, v.y, v.z])


def pose(p: Array, R: Array) -> common_pb2.Pose:
    q = rotation_to_quaternion(R)
    return common_pb2.Pose(
        x=float(p[0]),
        y=float(p[1]),
        z=float(p[2]),
        qx=float(q[0]),
        qy=float(q[1]),
        qz=float(q[2]),
        qw=float(q[3]),
    )


VISIBILITY_MSG: dict[Visibility, vision_pb2.Visibility] = {
    Visibility.WHOLE: vision_pb2.VISIBILITY_WHOLE,
    Visibility.CUT_BY_EDGE: vision_pb2.VISIBILITY_CUT_BY_EDGE,
    Visibility.OCCLUDED: vision_pb2.VISIBILITY_OCCLUDED,
}


def rgb(mean_rgb: Array | None) -> vision_pb2.Rgb | None:
    if mean_rgb is None:
        return None
    return vision_pb2.Rgb(r=float(mean_rgb[0]), g=float(mean_rgb[1]), b=float(mean_rgb[2]))


def detections_msg(result: DetectionResult, frame_id: str = "camera") -> vision_pb2.DetectedObjects:
    msg = vision_pb2.DetectedObjects(
        header=common_pb2.Header(stamp_ns=result.stamp_ns, frame_id=frame_id, seq=result.seq),
        notes=list(result.notes),
        rod_detected=result.rod_detected,
        calibrated=result.T_base_camera is not None,
    )
    msg.timings_ms.update({k: float(v) for k, v in result.timings_ms.items()})
    for r in result.rods:
        rod = msg.rods.add(
            center_camera=vec3(r.center_cam),
            axis_camera=vec3(r.axis_cam),
            pose_camera=pose(r.center_cam, r.rotation_cam),
            length_m=r.length_m,
            diameter_m=r.diameter_m,
            confidence=r.confidence,
            method=r.method,
            n_depth_points=r.n_depth_points,
        )
        R_base = r.rotation_base
        if r.center_base is not None and r.axis_base is not None and R_base is not None:
            rod.has_base = True
            rod.center_base.CopyFrom(vec3(r.center_base))
            rod.axis_base.CopyFrom(vec3(r.axis_base))
            rod.pose_base.CopyFrom(pose(r.center_base, R_base))
    for c in result.cubes:
        cube = msg.cubes.add(
            centroid_camera=vec3(c.centroid_cam),
            pose_camera=pose(c.centroid_cam, c.rotation_cam),
            color_label=c.color_label,
            n_points=c.n_points,
            visibility=VISIBILITY_MSG[c.visibility],
            mean_rgb=rgb(c.mean_rgb),
            fit_rms_m=c.fit_rms_m,
            hidden_fraction=c.hidden_fraction,
        )
        if c.centroid_base is not None and c.rotation_base is not None:
            cube.has_base = True
            cube.centroid_base.CopyFrom(vec3(c.centroid_base))
            cube.pose_base.CopyFrom(pose(c.centroid_base, c.rotation_base))
    for o in result.obstacles:
        box = msg.obstacles.add(
            camera=vision_pb2.BoxBounds(min=vec3(o.min_cam), max=vec3(o.max_cam)),
            color_label=o.color_label,
            n_points=o.n_points,
            visibility=VISIBILITY_MSG[o.visibility],
            mean_rgb=rgb(o.mean_rgb),
            recognised=o.recognised,
        )
        if o.min_base is not None and o.max_base is not None:
            box.has_base = True
            box.base.CopyFrom(vision_pb2.BoxBounds(min=vec3(o.min_base), max=vec3(o.max_base)))
    return msg
