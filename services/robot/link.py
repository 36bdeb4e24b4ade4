"""What the driver needs from a controller link: the one seam between the shared safety-checked
driver (:mod:`services.robot.driver`) and a vendor's protocol.

The Dobot V4 TCP/IP client (:class:`services.robot.client.DobotClient`) is one implementation; a UR
link over RTDE is another. Every safety rule lives in the driver above this seam, so a new robot
brand brings a link, never a copy of the checks. Feedback is presented in the driver's terms
(:class:`FeedbackState`: SI units, the controller's own clock in ``timestamp_ms``, robot modes as
:class:`services.dobot.RobotMode`), whatever the vendor's wire says.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

from numpy.typing import ArrayLike

from services.robot.feedback import ClientState, FeedbackState, LinkState

FeedbackListener = Callable[[FeedbackState], None]


class ControllerLink(Protocol):
    """A connection to one arm controller: its feedback stream, its motion queue and its I/O."""

    state: ClientState
    link: LinkState

    @property
    def feedback(self) -> FeedbackState | None:
        """The newest sound feedback packet (None before the first)."""
        ...

    async def connect(self) -> None: ...
    async def close(self) -> None: ...

    # feedback: every wait is on the controller's clock (``timestamp_ms``) or an event it reports
    def add_listener(self, callback: FeedbackListener) -> None: ...
    def remove_listener(self, callback: FeedbackListener) -> None: ...
    async def next_feedback(self, timeout_s: float | None = None) -> FeedbackState: ...
    async def wait_feedback(
        self, predicate: Callable[[FeedbackState], bool], timeout_s: float
    ) -> FeedbackState: ...
    async def wait_controller(
        self,
        predicate: Callable[[FeedbackState], bool],
        controller_timeout_s: float,
        *,
        since_ms: int | None = None,
        wall_guard_s: float | None = None,
    ) -> FeedbackState: ...
    async def wait_controller_time(self, duration_s: float, since_ms: int | None = None) -> FeedbackState: ...
    async def wait_motion_done(self, result_id: int | None, timeout_s: float) -> FeedbackState: ...

    # power, errors, stops
    async def enable(self, load_kg: float = 0.0) -> None: ...
    async def disable(self) -> None: ...
    async def clear_error(self) -> None: ...
    async def stop(self) -> None: ...
    async def emergency_stop(self, press: bool = True) -> None: ...
    async def describe_alarms(self) -> tuple[list[int], str]: ...

    # global speed and acceleration ratios, percent of the controller's rated values
    async def speed_factor(self, ratio: int) -> None: ...
    async def acceleration_ratio(self, ratio: int) -> None: ...

    # motion: joint targets in rad; each returns the controller's queue id of the command (None when
    # the controller does not number its commands)
    async def mov_j(
        self, q: ArrayLike, a: int | None = None, v: int | None = None, cp: int | None = None
    ) -> int | None: ...
    async def mov_l(self, q: ArrayLike, a: int | None = None, v: int | None = None) -> int | None: ...
    async def servo_j(self, q: ArrayLike, t_s: float) -> int | None: ...

    # I/O: the gripper's digital outputs (controller or tool connector)
    async def digital_output(
        self, index: int, on: bool, tool: bool = False, queued: bool = True
    ) -> int | None: ...


@runtime_checkable
class PipelinedServo(Protocol):
    """A link that can send several ServoJ targets in one write (the controller receives them
    together); the driver uses it when a link offers it, else one ``servo_j`` after another."""

    async def servo_j_many(self, qs: Sequence[ArrayLike], t_s: float) -> list[int | None]: ...
