"""The simulated controller's dashboard command set: one handler per V4 command, and the table.

A handler checks the command's parameters, acts on the :class:`~services.sim.controller.SimController`
(or queues a motion it starts when the command reaches the head of the queue) and returns the reply
values; a refused command raises :class:`~services.sim.command_args.CommandError`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from services import dobot
from services.common.frames import (
    dobot_pose_to_transform,
    make_transform,
    rpy_deg_to_matrix,
    transform_to_dobot_pose,
)
from services.kinematics import analytic
from services.sim.command_args import (
    PARAM_LIMIT_DEG,
    CommandError,
    joint_or_pose,
    nargs,
    opt_ratio,
    param_float,
    param_int,
    param_point,
)
from services.sim.motion_profiles import LinearInTime, Profile

if TYPE_CHECKING:
    from services.sim.controller import SimController

# what a handler answers: the reply values, or a preformatted value text
Handler = Callable[["SimController", dobot.ParsedCommand], "Sequence[object] | str"]


def _h_enable(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    if len(cmd.args) not in (0, 1, 4, 5):
        raise CommandError(dobot.ErrorID.PARAM_COUNT)
    if cmd.args:
        load = param_float(cmd.args[0], 1)
        if not 0 <= load <= 5:
            raise CommandError(-40001)
    ctl.enabled = True
    ctl.engine.hold()
    return []


def _h_disable(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    ctl.halt()
    ctl.enabled = False
    return []


def _h_clear_error(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    if ctl.estop:
        raise CommandError(dobot.ErrorID.ESTOP)
    ctl.alarms.clear()
    ctl.collision_state = False
    ctl.q_ref = ctl.measured.q.copy()
    return []


def _h_robot_mode(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    return [int(ctl.mode)]


def _h_get_error_id(ctl: SimController, cmd: dobot.ParsedCommand) -> str:
    nargs(cmd, 0)
    ids = ",".join(str(a) for a in ctl.alarms)
    if ctl.config.error_id_shape == "v45":
        return f"[[{ids}],[],[],[],[],[],[]]"
    return f"[{ids}]"


def _h_stop(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    ctl.halt()
    ctl.paused = False
    return []


def _h_pause(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    ctl.paused = True
    return []


def _h_continue(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    ctl.paused = False
    return []


def _h_estop(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0, 1)
    press = True if not cmd.args else bool(param_int(cmd.args[0], 1, 0, 1))
    if press:
        ctl.estop = True
        ctl.enabled = False
        ctl.raise_alarm(int(dobot.Alarm.ESTOP_PRESSED), "software emergency stop")
    else:
        ctl.estop = False
    return []


def _h_speed_factor(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 1)
    ctl.ratios.speed_factor = param_int(cmd.args[0], 1, 1, 100)
    return []


def _h_ratio(attr: str, lo: int = 1) -> Handler:
    def h(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
        nargs(cmd, 1)
        setattr(ctl.ratios, attr, param_int(cmd.args[0], 1, lo, 100))
        return []

    return h


def _h_get_angle(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    return [float(x) for x in np.rad2deg(ctl.measured.q)]


def _h_get_pose(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    if ("user" in cmd.kwargs) != ("tool" in cmd.kwargs):
        raise CommandError(-50001)
    return [float(x) for x in transform_to_dobot_pose(analytic.fk(ctl.spec, ctl.measured.q))]


def _h_positive_kin(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 6)
    q_deg = np.array([param_float(a, i + 1) for i, a in enumerate(cmd.args)])
    return [float(x) for x in transform_to_dobot_pose(analytic.fk(ctl.spec, np.deg2rad(q_deg)))]


def _h_inverse_kin(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 6)
    pose = np.array([param_float(a, i + 1) for i, a in enumerate(cmd.args)])
    seed = ctl.measured.q
    if cmd.kwargs.get("usejointnear", "0").strip() == "1" and "jointnear" in cmd.kwargs:
        seed = np.deg2rad(param_point(cmd.kwargs["jointnear"], 1))
    sols = analytic.solutions_within_limits(ctl.spec, dobot_pose_to_transform(pose), seed)
    if sols.shape[0] == 0:
        raise CommandError(dobot.ErrorID.FAILED)
    return [float(x) for x in np.rad2deg(sols[0])]


def _h_current_id(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 0)
    return [ctl.current_cmd_id]


def _h_movj(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    kind, target = joint_or_pose(cmd)
    a = opt_ratio(cmd, "a", ctl.ratios.acc_j)
    v = opt_ratio(cmd, "v", ctl.ratios.vel_j)
    opt_ratio(cmd, "cp", ctl.ratios.cp, lo=0)

    def run() -> Profile:
        if kind == "joint":
            q_goal = np.deg2rad(target)
        else:
            q_goal = ctl.ik_or_alarm(dobot_pose_to_transform(target), ctl.q_ref)
        return ctl.movj_to(q_goal, a, v)

    return ctl.enqueue("movj", run, cmd.raw)


def _h_movl(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    kind, target = joint_or_pose(cmd)
    a = opt_ratio(cmd, "a", ctl.ratios.acc_l)
    v = opt_ratio(cmd, "v", ctl.ratios.vel_l)
    speed = None
    if "speed" in cmd.kwargs:
        speed = float(param_int(cmd.kwargs["speed"], 1, 1, 10000, optional=True))

    def run() -> Profile:
        if kind == "joint":
            q_goal = np.deg2rad(target)
            ctl.check_target_limits(q_goal)
            return ctl.movl_to(analytic.fk(ctl.spec, q_goal), a, v, speed, q_goal_hint=q_goal)
        return ctl.movl_to(dobot_pose_to_transform(target), a, v, speed)

    return ctl.enqueue("movl", run, cmd.raw)


def _h_servoj(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 6)
    q_deg = np.array([param_float(a, i + 1) for i, a in enumerate(cmd.args)])
    if np.any(np.abs(q_deg) > PARAM_LIMIT_DEG):
        raise CommandError(-40001)
    t = 0.1
    if "t" in cmd.kwargs:
        t = param_float(cmd.kwargs["t"], 1, optional=True)
        if not 0.004 <= t <= 3600:
            raise CommandError(-60001)
    q_goal = np.deg2rad(q_deg)

    def run() -> Profile:
        ctl.check_target_limits(q_goal)
        speed = np.abs(q_goal - ctl.q_ref) / t
        over = np.nonzero(speed > ctl.spec.max_velocity * 1.05)[0]
        if over.size:
            j = int(over[0])
            ctl.raise_alarm(
                dobot.joint_overspeed_alarm(j),
                f"ServoJ asks joint {j + 1} for {np.rad2deg(speed[j]):.1f}°/s",
            )
            raise CommandError(dobot.ErrorID.ALARM)
        return LinearInTime(ctl.q_ref, q_goal, t)

    ids = ctl.enqueue("servoj", run, cmd.raw)
    ctl.servo_fed(t)
    return ids


def _h_rel_joint(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 6)
    d = np.deg2rad([param_float(x, i + 1) for i, x in enumerate(cmd.args)])
    a = opt_ratio(cmd, "a", ctl.ratios.acc_j)
    v = opt_ratio(cmd, "v", ctl.ratios.vel_j)
    return ctl.enqueue("reljointmovj", lambda: ctl.movj_to(ctl.q_ref + d, a, v), cmd.raw)


def _h_rel_cartesian(frame: str, linear: bool) -> Handler:
    def h(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
        nargs(cmd, 6)
        off = np.array([param_float(x, i + 1) for i, x in enumerate(cmd.args)])
        a = opt_ratio(cmd, "a", ctl.ratios.acc_l if linear else ctl.ratios.acc_j)
        v = opt_ratio(cmd, "v", ctl.ratios.vel_l if linear else ctl.ratios.vel_j)

        def run() -> Profile:
            T0 = analytic.fk(ctl.spec, ctl.q_ref)
            dT = make_transform(rpy_deg_to_matrix(off[3:]), off[:3] / 1000.0)
            if frame == "tool":
                T1 = T0 @ dT
            else:  # user frame = base: translate, rotate about the base axes at the TCP
                T1 = T0.copy()
                T1[:3, 3] = T0[:3, 3] + dT[:3, 3]
                T1[:3, :3] = dT[:3, :3] @ T0[:3, :3]
            if linear:
                return ctl.movl_to(T1, a, v, None)
            return ctl.movj_to(ctl.ik_or_alarm(T1, ctl.q_ref), a, v)

        return ctl.enqueue(cmd.key, run, cmd.raw)

    return h


def _h_do(tool: bool, instant: bool) -> Handler:
    def h(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
        nargs(cmd, 2, 3 if not instant and not tool else 2)
        index = param_int(cmd.args[0], 1, 1, 2 if tool else 64)
        on = bool(param_int(cmd.args[1], 2, 0, 1))
        if instant:
            ctl.set_do(index, on, tool)
            return []

        def run() -> Profile | None:
            ctl.set_do(index, on, tool)
            return None

        return ctl.enqueue(cmd.key, run, cmd.raw)

    return h


def _h_get_do(tool: bool) -> Handler:
    def h(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
        nargs(cmd, 1)
        index = param_int(cmd.args[0], 1, 1, 2 if tool else 64)
        mask = ctl.tool_do_mask if tool else ctl.do_mask
        return [(mask >> (index - 1)) & 1]

    return h


def _h_di(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
    nargs(cmd, 1)
    index = param_int(cmd.args[0], 1, 1, 64)
    return [(ctl.measured.digital_inputs >> (index - 1)) & 1]


def _h_noop(n: int) -> Handler:
    def h(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
        nargs(cmd, 0, n)
        return []

    return h


def _h_queue_noop(lo: int, hi: int) -> Handler:
    def h(ctl: SimController, cmd: dobot.ParsedCommand) -> list[object]:
        nargs(cmd, lo, hi)
        return ctl.enqueue(cmd.key, lambda: None, cmd.raw)

    return h


HANDLERS: dict[str, Handler] = {
    "enablerobot": _h_enable,
    "disablerobot": _h_disable,
    "clearerror": _h_clear_error,
    "robotmode": _h_robot_mode,
    "geterrorid": _h_get_error_id,
    "stop": _h_stop,
    "pause": _h_pause,
    "continue": _h_continue,
    "emergencystop": _h_estop,
    "speedfactor": _h_speed_factor,
    "accj": _h_ratio("acc_j"),
    "accl": _h_ratio("acc_l"),
    "velj": _h_ratio("vel_j"),
    "vell": _h_ratio("vel_l"),
    "cp": _h_ratio("cp", 0),
    "getangle": _h_get_angle,
    "getpose": _h_get_pose,
    "positivekin": _h_positive_kin,
    "inversekin": _h_inverse_kin,
    "getcurrentcommandid": _h_current_id,
    "movj": _h_movj,
    "movl": _h_movl,
    "servoj": _h_servoj,
    "reljointmovj": _h_rel_joint,
    "relmovjtool": _h_rel_cartesian("tool", False),
    "relmovltool": _h_rel_cartesian("tool", True),
    "relmovjuser": _h_rel_cartesian("user", False),
    "relmovluser": _h_rel_cartesian("user", True),
    "do": _h_do(False, False),
    "doinstant": _h_do(False, True),
    "tooldo": _h_do(True, False),
    "tooldoinstant": _h_do(True, True),
    "getdo": _h_get_do(False),
    "gettooldo": _h_get_do(True),
    "di": _h_di,
    "tooldi": _h_di,
    "poweron": _h_noop(0),
    "requestcontrol": _h_noop(0),
    "user": _h_queue_noop(1, 1),
    "tool": _h_queue_noop(1, 1),
    "setpayload": _h_queue_noop(1, 4),
    "setcollisionlevel": _h_queue_noop(1, 1),
}
