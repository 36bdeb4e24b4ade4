from services.common.protogen import proto_files, stale_files


def test_generated_code_is_current():
    assert proto_files(), "no .proto files found"
    stale = stale_files()
    assert stale == [], f"generated protobuf code is stale, run `make proto`: {stale}"


def test_messages_round_trip():
    from pickplace.v1 import common_pb2

    msg = common_pb2.JointState(name=["a", "b"], position=[0.1, -0.2], robot_mode=5)
    back = common_pb2.JointState.FromString(msg.SerializeToString())
    assert list(back.position) == [0.1, -0.2]
    assert back.robot_mode == 5
