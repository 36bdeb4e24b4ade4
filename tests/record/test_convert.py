"""Channels and conversions: schemas that describe themselves, FK as /tf, detections as a SceneUpdate."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from google.protobuf import descriptor_pb2
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory
from pickplace.v1 import common_pb2, motion_pb2, robot_pb2, vision_pb2
from scipy.spatial.transform import Rotation

from services.common.errors import InvalidInputError
from services.common.sensors import CameraIntrinsics
from services.kinematics.model import Kinematics, load_arm
from services.kinematics.robot_models import get_robot
from services.kinematics.tool import ToolGeometry
from services.kinematics.urdf import robot_urdf
from services.record import convert, scene
from services.record.channels import Encoding, Topic, channel_specs


def decode(topic: Topic, payload: bytes):  # type: ignore[no-untyped-def]
    spec = channel_specs()[topic]
    schema = Schema(id=1, name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data)
    fn = DecoderFactory().decoder_for(str(spec.message_encoding), schema)
    assert fn is not None
    return fn(payload)


def test_every_channel_carries_a_schema_that_describes_its_messages() -> None:
    specs = channel_specs()
    assert set(specs) == set(Topic)
    for spec in specs.values():
        if spec.message_encoding is Encoding.PROTOBUF:
            fds = descriptor_pb2.FileDescriptorSet.FromString(spec.schema_data)
            names = {f"{f.package}.{m.name}" for f in fds.file for m in f.message_type}
            assert spec.schema_name in names, spec.topic
        elif spec.message_encoding is Encoding.CDR:  # a ROS 2 message definition ROS 2's decoder reads
            from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

            schema = Schema(id=1, name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data)
            assert spec.schema_encoding == "ros2msg"
            assert Ros2DecoderFactory().decoder_for("cdr", schema) is not None, spec.topic
        else:
            assert spec.schema_encoding == "jsonschema"
            assert json.loads(spec.schema_data)["title"] == spec.schema_name


@pytest.mark.parametrize("model", ["nova5", "ur5e"])
def test_tf_chain_composes_to_the_kinematics_tool_pose(model: str) -> None:
    spec = get_robot(model)
    tool = ToolGeometry()
    T_base_camera = np.eye(4)
    T_base_camera[:3, 3] = [0.9, 0.0, 0.6]
    links = convert.LinkTransforms(spec, tool, T_base_camera)
    q = np.deg2rad([30.0, -20.0, 70.0, 10.0, -80.0, 45.0])
    msg = decode(Topic.TF, links.message(q, 123_000_000_001))
    parent_of = {}
    for tf in msg.transforms:
        T = np.eye(4)
        r = tf.rotation
        T[:3, :3] = Rotation.from_quat([r.x, r.y, r.z, r.w]).as_matrix()
        T[:3, 3] = [tf.translation.x, tf.translation.y, tf.translation.z]
        parent_of[tf.child_frame_id] = (tf.parent_frame_id, T)
        assert (tf.timestamp.seconds, tf.timestamp.nanos) == (123, 1)

    def in_base(frame: str) -> np.ndarray:
        T = np.eye(4)
        while frame != "base":
            frame, T_parent = parent_of[frame]
            T = T_parent @ T
        return T

    expected = Kinematics(load_arm(model, tool)).fk(q)
    assert np.allclose(in_base("tool_tip"), expected, atol=1e-6)
    assert np.allclose(in_base("camera"), T_base_camera)
    with pytest.raises(InvalidInputError, match="6 finite angles"):
        links.message(np.zeros(5), 0)


def test_the_urdf_for_foxglove_draws_every_collision_shape() -> None:
    urdf = convert.urdf_with_visuals(robot_urdf(get_robot("nova5")))
    root = ET.fromstring(urdf)
    for link in root.iter("link"):
        assert len(link.findall("visual")) == len(link.findall("collision")), link.get("name")
    assert sum(len(link.findall("visual")) for link in root.iter("link")) >= 7
    with pytest.raises(InvalidInputError, match="not valid URDF"):
        convert.urdf_with_visuals("<robot>")


def _vec(x: float, y: float, z: float) -> vision_pb2.Vec3:
    return vision_pb2.Vec3(x=x, y=y, z=z)


def test_detections_become_one_scene_update_in_the_base_frame_with_labels() -> None:
    objs = vision_pb2.DetectedObjects(header=common_pb2.Header(stamp_ns=5_000_000_000))
    objs.rods.add(
        has_base=True,
        pose_base=common_pb2.Pose(x=0.5, qw=1.0),
        length_m=0.2,
        diameter_m=0.022,
        confidence=0.9,
        method="surface_fit",
    )
    objs.cubes.add(has_base=False, pose_camera=common_pb2.Pose(z=0.8, qw=1.0), color_label="red")
    objs.obstacles.add(
        has_base=True,
        base=vision_pb2.BoxBounds(min=_vec(0.1, 0.1, 0.0), max=_vec(0.2, 0.3, 0.15)),
        color_label="blue",
    )
    update = decode(Topic.DETECTIONS, scene.scene_update(objs, "camera", 0.05))
    assert len(update.deletions) == 1  # the previous scene is replaced
    by_id = {e.id: e for e in update.entities}
    assert set(by_id) == {"rod0", "cube0", "obstacle0"}
    rod = by_id["rod0"]
    assert rod.frame_id == "base" and rod.cylinders[0].size.z == pytest.approx(0.2)
    # the cylinder's axis (its z) lies along the rod's x axis
    o = rod.cylinders[0].pose.orientation
    assert np.allclose(Rotation.from_quat([o.x, o.y, o.z, o.w]).apply([0, 0, 1]), [1, 0, 0], atol=1e-9)
    assert by_id["cube0"].frame_id == "camera" and by_id["cube0"].cubes[0].color.r > 0.8
    box = by_id["obstacle0"].cubes[0]
    assert (box.pose.position.x, box.size.y, box.size.z) == pytest.approx((0.15, 0.2, 0.15))
    assert "rod 0.90" in rod.texts[0].text and "red" in by_id["cube0"].texts[0].text


def test_robot_status_names_the_mode_and_each_alarm() -> None:
    view = json.loads(
        convert.robot_status_view(robot_pb2.RobotStatus(robot_mode=9, alarms=[117], connected=True))
    )
    assert view["mode_name"] == "ERROR"
    assert view["alarms"][0]["id"] == 117 and view["alarms"][0]["meaning"] not in ("", "alarm 117")


def test_camera_payloads_round_trip() -> None:
    intr = CameraIntrinsics(width=8, height=6, fx=500.0, fy=501.0, cx=4.0, cy=3.0)
    cal = decode(Topic.CAMERA_CALIBRATION, convert.camera_calibration(intr, 7, "camera"))
    assert list(cal.K)[:3] == [500.0, 0.0, 4.0] and cal.width == 8 and len(cal.P) == 12
    depth = np.arange(48, dtype=np.uint16).reshape(6, 8) * 100
    raw = decode(Topic.CAMERA_DEPTH, convert.depth_raw(depth, 7, "camera"))
    assert raw.encoding == "16UC1" and np.array_equal(np.frombuffer(raw.data, "<u2").reshape(6, 8), depth)
    jpg = decode(Topic.CAMERA_COLOR, convert.color_jpeg(np.full((6, 8, 3), 200, np.uint8), 7, "camera", 90))
    assert jpg.format == "jpeg" and jpg.data[:2] == b"\xff\xd8"


def test_the_plan_is_one_line_through_the_tool_path_and_the_scene_holds_table_and_boxes() -> None:
    xyz = np.array([[0.4, 0.0, 0.3], [0.45, 0.05, 0.2], [0.5, 0.1, 0.1]])
    line = decode(Topic.PLAN, scene.plan_line(xyz, 9, "GRASP"))
    (entity,) = line.entities
    assert entity.frame_id == "base" and len(entity.lines) == 1
    assert [(p.x, p.y, p.z) for p in entity.lines[0].points] == [tuple(r) for r in xyz]
    box = motion_pb2.CollisionBox(name="obstacle0", x_min=0.1, x_max=0.2, y_min=-0.1, y_max=0.1, z_max=0.15)
    update = decode(Topic.PLANNING_SCENE, scene.planning_scene([box], 0.0, 0.01, 9))
    by_id = {e.id: e for e in update.entities}
    assert set(by_id) == {"table", "box:obstacle0"}
    assert by_id["box:obstacle0"].cubes[0].size.x == pytest.approx(0.1)
    assert "+10 mm" in by_id["box:obstacle0"].texts[0].text
    assert by_id["table"].cubes[0].pose.position.z < 0  # the table's top at table_z
