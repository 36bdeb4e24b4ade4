"""The Dobot dashboard commands in SI units (radians, metres, 4x4 transforms): each one a command
string from :mod:`services.dobot`, sent by the client's :meth:`DobotCommands.request`, and its reply
parsed. Degrees and millimetres exist only in the strings sent and parsed here.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from services import dobot
from services.common.errors import ControllerError, EmergencyStopError
from services.common.frames import dobot_pose_to_transform, finite_vector, transform_to_dobot_pose


def _deg(v_rad: np.ndarray) -> list[float]:
    """Radians → degrees, as the plain floats the command codec formats."""
    return np.rad2deg(v_rad).tolist()


def _pose(T: np.ndarray) -> list[float]:
    """A transform → the controller's pose (mm, degrees), as plain floats."""
    return transform_to_dobot_pose(T).tolist()


def raise_for_reply(command: str, reply: dobot.Reply) -> None:
    """ControllerError (or EmergencyStopError) unless the reply's ErrorID is 0."""
    if reply.error_id == dobot.ErrorID.ESTOP:
        raise EmergencyStopError(f"{command} refused: {dobot.describe_error_id(reply.error_id)}")
    if reply.error_id != 0:
        raise ControllerError(
            f"{command} refused with ErrorID {reply.error_id}: {dobot.describe_error_id(reply.error_id)}",
            error_id=reply.error_id,
        )


class DobotCommands:
    """The typed commands over :meth:`request` / :meth:`raw_requests`, which the client provides."""

    async def request(self, command: str, timeout_s: float | None = None) -> dobot.Reply:
        raise NotImplementedError

    async def raw_requests(
        self, commands: Sequence[str], timeout_s: float | None = None
    ) -> list[dobot.Reply]:
        raise NotImplementedError

    async def enable(self, load_kg: float = 0.0) -> None:
        await self.request(dobot.enable_robot(load_kg))

    async def disable(self) -> None:
        await self.request("DisableRobot()")

    async def clear_error(self) -> None:
        await self.request("ClearError()")

    async def robot_mode(self) -> int:
        return int((await self.request("RobotMode()")).floats()[0])

    async def error_ids(self) -> list[int]:
        reply = await self.request("GetErrorID()")
        return dobot.parse_error_ids(reply.values_text)

    async def current_command_id(self) -> int:
        return int((await self.request("GetCurrentCommandID()")).floats()[0])

    async def get_angles(self) -> np.ndarray:
        return np.deg2rad((await self.request("GetAngle()")).floats())

    async def get_pose(self) -> np.ndarray:
        return dobot_pose_to_transform((await self.request("GetPose()")).floats())

    async def speed_factor(self, ratio: int) -> None:
        await self.request(dobot.speed_factor(ratio))

    async def acceleration_ratio(self, ratio: int) -> None:
        """AccJ and AccL at once: the acceleration percentage of MovJ / MovL without their own ``a=``."""
        for cmd in dobot.acceleration_ratios(ratio):
            await self.request(cmd)

    async def stop(self) -> None:
        await self.request("Stop()")

    async def positive_kin(self, q: ArrayLike) -> np.ndarray:
        q_rad = finite_vector(q, 6, "joints")
        return dobot_pose_to_transform((await self.request(dobot.positive_kin(_deg(q_rad)))).floats())

    async def inverse_kin(self, T: np.ndarray, joint_near: ArrayLike | None = None) -> np.ndarray:
        near = None if joint_near is None else _deg(finite_vector(joint_near, 6, "joint_near"))
        reply = await self.request(dobot.inverse_kin(_pose(T), near))
        return np.deg2rad(reply.floats())

    async def digital_output(
        self, index: int, on: bool, tool: bool = False, queued: bool = True
    ) -> int | None:
        if queued:
            return (await self.request(dobot.digital_output(index, on, tool))).result_id
        name = "ToolDOInstant" if tool else "DOInstant"
        await self.request(dobot.command(name, dobot.fmt_int(index), "1" if on else "0"))
        return None

    async def digital_input(self, index: int, tool: bool = False) -> bool:
        reply = await self.request(dobot.command("ToolDI" if tool else "DI", dobot.fmt_int(index)))
        return bool(int(reply.floats()[0]))

    async def mov_j(
        self, q: ArrayLike, a: int | None = None, v: int | None = None, cp: int | None = None
    ) -> int | None:
        q_rad = finite_vector(q, 6, "joint target")
        return (await self.request(dobot.mov_j_joint(_deg(q_rad), a, v, cp))).result_id

    async def mov_j_pose(self, T: np.ndarray, a: int | None = None, v: int | None = None) -> int | None:
        return (await self.request(dobot.mov_j_pose(_pose(T), a, v))).result_id

    async def mov_l(self, q: ArrayLike, a: int | None = None, v: int | None = None) -> int | None:
        q_rad = finite_vector(q, 6, "joint target")
        return (await self.request(dobot.mov_l_joint(_deg(q_rad), a, v))).result_id

    async def mov_l_pose(
        self, T: np.ndarray, a: int | None = None, v: int | None = None, speed_m_s: float | None = None
    ) -> int | None:
        speed = None if speed_m_s is None else max(1, round(speed_m_s * 1000))
        return (await self.request(dobot.mov_l_pose(_pose(T), a, v, speed))).result_id

    async def servo_j(self, q: ArrayLike, t_s: float) -> int | None:
        q_rad = finite_vector(q, 6, "servo target")
        return (await self.request(dobot.servo_j(_deg(q_rad), t_s))).result_id

    async def servo_j_many(self, qs: Sequence[ArrayLike], t_s: float) -> list[int | None]:
        """ServoJ targets pipelined in one write (the controller queues them together, so none can find
        it run dry behind another); their queue IDs. ControllerError (EmergencyStopError) at the first
        refused, as :meth:`request`."""
        commands = [dobot.servo_j(_deg(finite_vector(q, 6, "servo target")), t_s) for q in qs]
        replies = await self.raw_requests(commands)
        for command, reply in zip(commands, replies, strict=True):
            raise_for_reply(command, reply)
        return [r.result_id for r in replies]

    async def rel_mov_l_tool(
        self, offset_m_rad: ArrayLike, a: int | None = None, v: int | None = None
    ) -> int | None:
        o = finite_vector(offset_m_rad, 6, "offset")
        mm_deg = [*(o[:3] * 1000.0).tolist(), *_deg(o[3:])]
        return (await self.request(dobot.rel_mov_l_tool(mm_deg, a, v))).result_id

    async def rel_mov_j_tool(
        self, offset_m_rad: ArrayLike, a: int | None = None, v: int | None = None
    ) -> int | None:
        o = finite_vector(offset_m_rad, 6, "offset")
        mm_deg = [*(o[:3] * 1000.0).tolist(), *_deg(o[3:])]
        return (await self.request(dobot.rel_mov_j_tool(mm_deg, a, v))).result_id

    async def rel_joint_mov_j(self, dq: ArrayLike, a: int | None = None, v: int | None = None) -> int | None:
        d = finite_vector(dq, 6, "joint offsets")
        return (await self.request(dobot.rel_joint_mov_j(_deg(d), a, v))).result_id

    async def describe_alarms(self) -> tuple[list[int], str]:
        try:
            ids = await self.error_ids()
        except Exception as exc:  # the alarm itself matters more than why we couldn't read it
            return [], f"(GetErrorID failed: {exc})"
        return ids, ", ".join(f"{i}: {dobot.describe_alarm(i)}" for i in ids) or "no alarm IDs reported"
