"""The simulated controller's protocol semantics, driven directly (no sockets)."""

import numpy as np
import pytest

from services import dobot
from services.common.frames import dobot_pose_to_transform
from services.kinematics import analytic
from services.kinematics.robot_models import NOVA5
from services.sim.controller import ControllerConfig, SimController
from services.sim.engine import KinematicEngine

HOME = np.deg2rad([0, 0, 90, 0, -90, 0])


@pytest.fixture
def ctrl() -> SimController:
    c = SimController(NOVA5, KinematicEngine(), q0=HOME, clock_ms=lambda: 1_700_000_000_000)
    assert c.handle("EnableRobot()").startswith("0,")
    return c


def run(c: SimController, seconds: float, dt: float = 0.008) -> None:
    for _ in range(round(seconds / dt)):
        c.tick(dt)


def reply(c: SimController, cmd: str) -> dobot.Reply:
    return dobot.parse_reply(c.handle(cmd))


def test_disabled_until_enabled():
    c = SimController(NOVA5, KinematicEngine(), q0=HOME)
    assert reply(c, "RobotMode()").floats() == [4]
    assert reply(c, "MovJ(joint={0,0,90,0,-90,0})").error_id == -1  # not enabled
    assert reply(c, "ENABLEROBOT()").ok  # names are case-insensitive
    assert reply(c, "RobotMode()").floats() == [5]


def test_movj_runs_queue_ids_and_modes(ctrl):
    r1 = reply(ctrl, "MovJ(joint={10,20,30,40,50,60})")
    r2 = reply(ctrl, "MovJ(joint={0,0,90,0,-90,0},v=100,a=100)")
    assert (r1.result_id, r2.result_id) == (1, 2)
    ctrl.tick(0.008)
    assert ctrl.mode == dobot.RobotMode.RUNNING and ctrl.current_cmd_id == 1
    run(ctrl, 10)
    assert ctrl.mode == dobot.RobotMode.ENABLE and ctrl.current_cmd_id == 2
    assert np.allclose(reply(ctrl, "GetAngle()").floats(), [0, 0, 90, 0, -90, 0], atol=1e-6)


def test_movj_respects_speed_limits(ctrl):
    reply(ctrl, "MovJ(joint={90,0,90,0,-90,0},v=100)")
    speeds = []
    for _ in range(400):
        ctrl.tick(0.008)
        speeds.append(np.abs(ctrl.qd_ref))
    vmax = np.minimum(NOVA5.max_velocity, np.deg2rad(ctrl.config.max_joint_speed_deg_s))
    assert np.max(np.array(speeds) / vmax) <= 1.0 + 1e-9
    assert np.isclose(np.rad2deg(ctrl.measured.q[0]), 90, atol=1e-6)


def test_feedback_consistent_with_fk(ctrl):
    reply(ctrl, "MovJ(joint={10,20,30,40,50,60})")
    run(ctrl, 5)
    rec = dobot.decode_feedback(ctrl.feedback_bytes())
    q = np.deg2rad(rec["QActual"])
    T = dobot_pose_to_transform(rec["ToolVectorActual"])
    assert np.allclose(T, analytic.fk(NOVA5, q), atol=1e-9)
    # spec reference: q = (10,20,30,40,50,60)° → (−468.557, −277.357, 895.660) mm
    assert np.allclose(rec["ToolVectorActual"][:3], [-468.557, -277.357, 895.660], atol=0.01)
    assert int(rec["EnableStatus"]) == 1 and int(rec["CRRobotType"]) == 103
    # the controller's clock is sim time from the boot epoch: 5 s of ticks later, 5 s later in the stamp
    assert int(rec["TimeStamp"]) == 1_700_000_000_000 + round(ctrl.sim_time * 1000)
    assert int(rec["RunTime"]) == round(ctrl.sim_time * 1000) >= 5000


def test_joint_limit_alarm_then_clear(ctrl):
    assert reply(ctrl, "MovJ(joint={0,0,170,0,0,0})").ok  # J3 limit is ±159.9°
    ctrl.tick(0.008)
    assert ctrl.mode == dobot.RobotMode.ERROR
    assert dobot.parse_error_ids(reply(ctrl, "GetErrorID()").values_text) == [68]
    assert reply(ctrl, "GetAngle()").error_id == -2  # refused in alarm
    assert reply(ctrl, "MovJ(joint={0,0,90,0,-90,0})").error_id == -2
    assert reply(ctrl, "ClearError()").ok
    assert ctrl.mode == dobot.RobotMode.ENABLE
    assert reply(ctrl, "MovJ(joint={0,0,100,0,-90,0})").ok


def test_unreachable_pose_alarms(ctrl):
    assert reply(ctrl, "MovJ(pose={2000,0,300,180,0,0})").ok
    ctrl.tick(0.008)
    assert ctrl.mode == dobot.RobotMode.ERROR
    assert dobot.parse_error_ids(reply(ctrl, "GetErrorID()").values_text) == [17]


def test_movl_follows_a_straight_line(ctrl):
    start = reply(ctrl, "GetPose()").floats()
    goal = list(start)
    goal[0] += 100.0
    goal[2] -= 80.0
    assert reply(ctrl, "MovL(pose={" + ",".join(f"{v:f}" for v in goal) + "})").ok
    pts = []
    for _ in range(500):
        ctrl.tick(0.008)
        pts.append(analytic.fk(NOVA5, ctrl.measured.q)[:3, 3] * 1000)
    pts = np.array(pts)
    a, b = np.array(start[:3]), np.array(goal[:3])
    d = (b - a) / np.linalg.norm(b - a)
    off_line = np.linalg.norm((pts - a) - np.outer((pts - a) @ d, d), axis=1)
    assert off_line.max() < 1.0  # mm
    assert np.allclose(pts[-1], b, atol=1e-3)


def test_malformed_commands_get_protocol_codes(ctrl):
    assert reply(ctrl, "Sync()").error_id == -10000  # not in V4
    assert reply(ctrl, "MovJ(joint={999,0,0,0,0,0})").error_id == -40001
    assert reply(ctrl, "MovJ(joint={a,0,0,0,0,0})").error_id == -30001
    assert reply(ctrl, "SpeedFactor()").error_id == -20000
    assert reply(ctrl, "SpeedFactor(200)").error_id == -40001
    assert reply(ctrl, "MovJ(joint={0,0,90,0,-90,0},a=200)").error_id == -60001
    assert reply(ctrl, "DO(1)").error_id == -20000
    assert reply(ctrl, "RobotMode()").ok  # still serving


def test_estop_gates_commands(ctrl):
    reply(ctrl, "MovJ(joint={90,0,90,0,-90,0})")
    run(ctrl, 0.2)
    assert reply(ctrl, "EmergencyStop(1)").ok
    q_stop = ctrl.measured.q.copy()
    run(ctrl, 0.5)
    assert np.allclose(ctrl.measured.q, q_stop)  # nothing moves
    assert reply(ctrl, "EnableRobot()").error_id == -3
    assert reply(ctrl, "ClearError()").error_id == -3  # release first
    assert 116 in dobot.parse_error_ids(reply(ctrl, "GetErrorID()").values_text)
    assert reply(ctrl, "EmergencyStop(0)").ok
    assert reply(ctrl, "ClearError()").ok
    assert reply(ctrl, "EnableRobot()").ok
    assert ctrl.mode == dobot.RobotMode.ENABLE


def test_stop_clears_queue(ctrl):
    reply(ctrl, "MovJ(joint={90,0,90,0,-90,0})")
    reply(ctrl, "MovJ(joint={-90,0,90,0,-90,0})")
    run(ctrl, 0.1)
    assert reply(ctrl, "Stop()").ok
    run(ctrl, 0.1)
    assert ctrl.mode == dobot.RobotMode.ENABLE and not ctrl.queue


def test_do_is_queued_and_reaches_engine(ctrl):
    outputs: list[int] = []

    class Recorder(KinematicEngine):
        def set_digital_outputs(self, mask: int) -> None:
            outputs.append(mask)

    c = SimController(NOVA5, Recorder(), q0=HOME)
    c.handle("EnableRobot()")
    c.handle("MovJ(joint={10,0,90,0,-90,0})")
    rid = dobot.parse_reply(c.handle("DO(1,1)")).result_id
    assert rid == 2 and (c.do_mask & 1) == 0  # waits behind the move
    run(c, 3)
    assert c.do_mask & 1 and outputs[-1] & 1
    assert dobot.parse_reply(c.handle("GetDO(1)")).floats() == [1]
    c.handle("ToolDOInstant(1,1)")
    assert outputs[-1] >> 32 & 1  # flange outputs sit above bit 32


def test_servoj_overspeed_alarms(ctrl):
    assert reply(ctrl, "ServoJ(90,0,90,0,-90,0,t=0.01)").ok
    ctrl.tick(0.008)
    assert 48 in dobot.parse_error_ids(reply(ctrl, "GetErrorID()").values_text)


def test_inverse_and_positive_kin(ctrl):
    pose = reply(ctrl, "PositiveKin(10,20,30,40,50,60)").floats()
    q = reply(
        ctrl,
        "InverseKin(" + ",".join(f"{v:f}" for v in pose) + ",useJointNear=1,jointNear={10,20,30,40,50,60})",
    )
    assert np.allclose(q.floats(), [10, 20, 30, 40, 50, 60], atol=1e-6)


def test_collision_from_engine_raises_117():
    class Crashing(KinematicEngine):
        def step(self, dt, q_ref, qd_ref, qdd_ref):  # type: ignore[no-untyped-def]
            st = super().step(dt, q_ref, qd_ref, qdd_ref)
            st.collision = "link4 hit the table"
            return st

    c = SimController(NOVA5, Crashing(), q0=HOME)
    c.handle("EnableRobot()")
    c.tick(0.008)
    assert c.mode == dobot.RobotMode.COLLISION
    assert dobot.parse_error_ids(dobot.parse_reply(c.handle("GetErrorID()")).values_text) == [117]


def _servo_stream(c: SimController, start_deg: float, n: int, step_deg: float, t: float) -> list[int]:
    """Queue ``n`` ServoJ targets at once (a host's look-ahead), J1 advancing ``step_deg`` each."""
    ids = []
    for k in range(1, n + 1):
        r = reply(c, f"ServoJ({start_deg + k * step_deg:.6f},0,90,0,-90,0,t={t})")
        assert r.ok
        ids.append(r.result_id)
    return ids


def _ticks_until_rest(c: SimController, limit_s: float, dt: float = 0.008) -> float:
    """Tick until the arm is at rest with nothing queued; the sim time that took."""
    t0 = c.sim_time
    while c.sim_time - t0 < limit_s:
        c.tick(dt)
        if c.mode == dobot.RobotMode.ENABLE and not np.any(c.measured.qd):
            return c.sim_time - t0
    raise AssertionError(f"still moving after {limit_s}s of sim time")


def test_a_starved_servoj_stream_holds_its_last_target_once_its_t_runs_out(ctrl):
    # today's (and a real controller's) behaviour without the watchdog: each ServoJ reaches its target
    # in exactly t and holds it; a stream that is not fed ends when its queue runs dry
    ids = _servo_stream(ctrl, 0.0, 10, 0.5, 0.032)
    took = _ticks_until_rest(ctrl, 2.0)
    assert took <= 10 * 0.032 + 2 * 0.008  # the whole look-ahead ran, then the arm stopped
    assert ctrl.current_cmd_id == ids[-1] and ctrl.servo_watchdog_trips == 0
    assert np.isclose(np.rad2deg(ctrl.measured.q[0]), 5.0, atol=1e-6)
    q = ctrl.measured.q.copy()
    run(ctrl, 0.5)
    assert np.array_equal(ctrl.measured.q, q)


def test_servoj_watchdog_stops_a_stream_not_fed_within_t_plus_margin():
    c = SimController(
        NOVA5,
        KinematicEngine(),
        ControllerConfig(servo_watchdog_margin_s=0.016),
        q0=HOME,
        clock_ms=lambda: 1_700_000_000_000,
    )
    assert reply(c, "EnableRobot()").ok
    t = 0.032
    # a host feeding one target per t, keeping a look-ahead of 4: never trips
    _servo_stream(c, 0.0, 4, 0.5, t)
    deg = 2.0
    for _ in range(20):
        run(c, t)
        deg += 0.5
        assert reply(c, f"ServoJ({deg:.6f},0,90,0,-90,0,t={t})").ok
    assert c.servo_watchdog_trips == 0 and c.mode == dobot.RobotMode.RUNNING
    # the host dies with 4 targets (0.128 s of motion) queued: the arm is halted t + margin later
    fed_at = c.sim_time
    took = _ticks_until_rest(c, 2.0)
    assert c.servo_watchdog_trips == 1
    assert c.sim_time - fed_at <= t + 0.016 + 0.008 + 1e-9
    assert took < 4 * t  # not the whole look-ahead
    assert np.rad2deg(c.measured.q[0]) < deg - 0.5  # short of the last target sent
    q = c.measured.q.copy()
    run(c, 0.5)
    assert np.array_equal(c.measured.q, q) and not c.queue
    # no alarm: a new stream runs
    assert c.mode == dobot.RobotMode.ENABLE
    _servo_stream(c, float(np.rad2deg(q[0])), 1, 0.5, t)
    _ticks_until_rest(c, 1.0)
    assert c.servo_watchdog_trips == 1


def test_servoj_watchdog_leaves_other_motion_alone():
    c = SimController(NOVA5, KinematicEngine(), ControllerConfig(servo_watchdog_margin_s=0.016), q0=HOME)
    assert reply(c, "EnableRobot()").ok
    _servo_stream(c, 0.0, 1, 0.5, 0.032)
    _ticks_until_rest(c, 1.0)  # a stream that ended within its t is over: nothing to watch
    assert reply(c, "MovJ(joint={30,0,90,0,-90,0})").ok
    _ticks_until_rest(c, 10.0)
    assert c.servo_watchdog_trips == 0 and np.isclose(np.rad2deg(c.measured.q[0]), 30.0, atol=1e-6)
