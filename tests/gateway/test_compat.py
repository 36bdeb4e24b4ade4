"""A client generated from the LLD's proto text (§13.2, package robot_control) talks to the cell.

The client runs in its own process, with stubs that protoc generates there from the LLD's text (the
three messages the LLD names without defining, Empty, GraspPose and GraspResponse, as the cell's
proto defines them); it knows nothing of pickplace.v1.
"""

from __future__ import annotations

import asyncio
import json
import sys
import textwrap

import numpy as np
import pytest

from services.common.bus import Bus
from services.common.keys import CellKeys
from services.robot.service import RobotService
from tests.gateway.conftest import (
    TOKEN,
    gateway_settings,
    migrate_up,
    pick_event,
    running_gateway,
    wait_until,
)

pytestmark = pytest.mark.integration

# LLD §13.2, robot_interfaces/proto/robot_control.proto, as written there
LLD_PROTO = """
syntax = "proto3";

package robot_control;

service RobotController {
    rpc GetJointStates(Empty) returns (JointStates);
    rpc MoveJoints(JointPositions) returns (MoveResponse);
    rpc ExecuteGrasp(GraspPose) returns (GraspResponse);
    rpc StreamMetrics(Empty) returns (stream Metrics);
}

message JointStates {
    repeated double positions = 1; // 6 DOF
    repeated double velocities = 2;
    repeated double efforts = 3;
    int64 timestamp = 4;
}

message JointPositions {
    repeated double positions = 1;
    double max_velocity = 2;
    double max_acceleration = 3;
}

message MoveResponse {
    bool success = 1;
    string message = 2;
    double execution_time = 3;
}

message Metrics {
    double cycle_time = 1;
    double success_rate = 2;
    int32 picks_today = 3;
}
"""
# named by the LLD, not defined there
UNDEFINED_IN_LLD = """
message Empty {}
message GraspPose {
    double x = 1; double y = 2; double z = 3;
    double qx = 4; double qy = 5; double qz = 6; double qw = 7;
    double approach_distance = 8; double lift_distance = 9;
}
message GraspResponse { bool success = 1; string message = 2; bool object_detected = 3; }
"""

CLIENT = textwrap.dedent(
    """
    import json, math, sys
    from pathlib import Path
    from grpc_tools import protoc
    work = Path(sys.argv[1]); port = sys.argv[2]; token = sys.argv[3]
    assert protoc.main(["protoc", f"-I{work}", f"--python_out={work}", f"--grpc_python_out={work}",
                        str(work / "robot_control.proto")]) == 0
    sys.path.insert(0, str(work))
    import grpc, robot_control_pb2 as pb, robot_control_pb2_grpc as rpc
    md = (("authorization", f"Bearer {token}"),)
    out = {}
    with grpc.insecure_channel(f"127.0.0.1:{port}") as ch:
        stub = rpc.RobotControllerStub(ch)
        try:
            stub.GetJointStates(pb.Empty(), timeout=10)
        except grpc.RpcError as e:
            out["no_token"] = e.code().name
        js = stub.GetJointStates(pb.Empty(), metadata=md, timeout=10)
        out["positions"] = list(js.positions); out["timestamp"] = js.timestamp
        out["velocities"] = len(js.velocities)
        target = [math.radians(d) for d in (10, 5, 85, 0, -90, 0)]
        r = stub.MoveJoints(pb.JointPositions(positions=target, max_velocity=2.0), metadata=md, timeout=30)
        out["move"] = [r.success, r.message, r.execution_time]
        out["after_move"] = list(stub.GetJointStates(pb.Empty(), metadata=md, timeout=10).positions)
        try:
            stub.MoveJoints(pb.JointPositions(positions=[0, 0, 3.0, 0, 0, 0]), metadata=md, timeout=10)
        except grpc.RpcError as e:
            out["refused"] = [e.code().name, e.details()]
        try:
            g = stub.ExecuteGrasp(pb.GraspPose(x=0.45, y=0.0, z=0.12, qx=1.0, qw=0.0), metadata=md, timeout=60)
            out["grasp"] = ["ok", g.success, g.message]
        except grpc.RpcError as e:  # the driver's error, passed through with its code and type
            out["grasp"] = ["error", e.code().name, e.details()]
        out["after_grasp"] = list(stub.GetJointStates(pb.Empty(), metadata=md, timeout=10).positions)
        for m in stub.StreamMetrics(pb.Empty(), metadata=md, timeout=10):
            out["metrics"] = [m.cycle_time, m.success_rate, m.picks_today]
            break
    print(json.dumps(out))
    """
)


async def test_a_client_generated_from_the_lld_proto_drives_the_cell(
    robot_settings, sim_server, sqlite_db, tmp_path
) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "robot_control.proto").write_text(LLD_PROTO + UNDEFINED_IN_LLD)
    await migrate_up(sqlite_db)
    s = gateway_settings(robot_settings, sqlite_db, tmp_path, edge_grpc_port=0)
    async with Bus(s.zenoh) as bus, RobotService(s, bus, grpc_port=0) as robot:
        await robot.driver.enable()
        s = s.model_copy(update={"grpc": s.grpc.model_copy(update={"robot_port": robot.grpc_port})})
        async with running_gateway(s, bus) as gw:
            bus.publish(CellKeys(s.cell_id).pick_events, pick_event(0))
            await wait_until(lambda: gw.cell.writer.written == 1, 5.0, "a pick in the database")
            proc = await asyncio.create_subprocess_exec(
                sys.executable,
                "-c",
                CLIENT,
                str(tmp_path),
                str(gw.cell.edge_port),
                TOKEN,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.PIPE,
            )
            out, err = await proc.communicate()
    assert proc.returncode == 0, err.decode()[-3000:]
    r = json.loads(out)
    assert r["no_token"] == "UNAUTHENTICATED"
    assert np.allclose(np.rad2deg(r["positions"]), [0, 0, 90, 0, -90, 0], atol=1e-6)
    assert r["timestamp"] > 0 and r["velocities"] == 6
    assert r["move"][0] and r["move"][2] > 0, r["move"]
    assert np.allclose(np.rad2deg(r["after_move"]), [10, 5, 85, 0, -90, 0], atol=1e-4)
    assert r["refused"][0] == "OUT_OF_RANGE" or "joint 3" in r["refused"][1], r["refused"]
    # the grasp drove the arm (approach, close, lift); on a loaded machine the driver may stop the
    # stream and say why: then its error arrives with the pickplace error type, as from pickplace.v1
    assert not np.allclose(r["after_grasp"], r["after_move"], atol=1e-3), r["grasp"]
    if r["grasp"][0] == "ok":
        assert r["grasp"][1] and r["grasp"][2], r["grasp"]
    else:
        assert r["grasp"][2].split(":")[0].endswith("Error"), r["grasp"]
    assert r["metrics"] == [pytest.approx(8.0), 1.0, 1]
