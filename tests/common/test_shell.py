"""The one shape of a service shell: state, one task group, misuse raises, health over gRPC."""

from __future__ import annotations

import asyncio
import contextlib

import grpc
import pytest

from services.common import grpc_util
from services.common.errors import RobotCommunicationError
from services.common.shell import GrpcShell, ServiceShell, ShellState, ShellStateError


class Recorder(ServiceShell):
    kind = "recorder"

    def __init__(self, fail_start: bool = False) -> None:
        super().__init__()
        self.fail_start = fail_start
        self.events: list[str] = []
        self.forever: asyncio.Task[None] | None = None

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        self.events.append(f"start:{self.state.value}")
        stack.callback(self.events.append, "released")
        self.forever = self.spawn(asyncio.Event().wait(), "forever")  # type: ignore[arg-type]
        if self.fail_start:
            raise RobotCommunicationError("the link did not come up")


async def test_a_shell_goes_through_its_states_and_its_work_ends_with_it() -> None:
    shell = Recorder()
    assert shell.state is ShellState.NEW
    async with shell:
        assert shell.state is ShellState.RUNNING and shell.health().serving
        assert shell.forever is not None and not shell.forever.done()
        assert shell.forever.get_name() == "recorder.forever"
    assert shell.state is ShellState.STOPPED and not shell.health().serving
    assert shell.forever.cancelled()  # nothing outlives its service
    assert shell.events == ["start:starting", "released"]


async def test_misuse_raises_a_clear_error() -> None:
    shell = Recorder()
    with pytest.raises(ShellStateError, match="recorder service is new"):
        await shell.wait()
    async with shell:
        with pytest.raises(ShellStateError, match="entered once"):
            await shell.__aenter__()
    with pytest.raises(ShellStateError, match="recorder service is stopped: a shell is entered once"):
        async with shell:
            pass
    with pytest.raises(ShellStateError, match="cannot start 'late'"):
        shell.spawn(asyncio.sleep(0), "late")
    with pytest.raises(ShellStateError, match="is stopped"):
        await shell.wait()


async def test_a_failed_start_releases_what_it_took_and_raises_its_own_error() -> None:
    shell = Recorder(fail_start=True)
    with pytest.raises(RobotCommunicationError, match="did not come up"):
        async with shell:
            pytest.fail("the body must not run")
    assert shell.state is ShellState.STOPPED
    assert shell.events == ["start:starting", "released"]
    assert shell.forever is not None and shell.forever.cancelled()


async def test_a_failing_background_task_stops_the_service_with_its_error() -> None:
    async def broken() -> None:
        await asyncio.sleep(0)
        raise ValueError("the loop broke")

    shell = Recorder()
    with pytest.raises(ValueError, match="the loop broke"):
        async with shell:
            shell.spawn(broken(), "broken")
            await shell.wait()  # the task group cancels the waiting task; the error comes out on exit
    assert shell.state is ShellState.STOPPED and shell.events[-1] == "released"


class Linked(GrpcShell):
    kind = "linked"

    def __init__(self) -> None:
        super().__init__("127.0.0.1", 0)
        self.link_up = True

    async def _start(self, stack: contextlib.AsyncExitStack) -> None:
        await self._serve_grpc(stack, lambda server: None, "nothing")

    def links(self) -> dict[str, bool]:
        return {"the link": self.link_up}


async def test_grpc_health_follows_the_shells_links() -> None:
    async with Linked() as shell:
        said = await grpc_util.check_health("127.0.0.1", shell.grpc_port, "linked")
        assert "serving" in said and "the link up" in said
        shell.link_up = False
        with pytest.raises(RobotCommunicationError, match="NOT_SERVING: running, the link DOWN"):
            await grpc_util.check_health("127.0.0.1", shell.grpc_port, "linked")
        port = shell.grpc_port
    assert shell.server is None
    with pytest.raises(RobotCommunicationError, match="not answering its health check"):
        await grpc_util.check_health("127.0.0.1", port, "linked", timeout_s=0.5)


async def test_health_check_is_plain_grpc_health_v1() -> None:
    """Any standard client can ask: the request and reply are grpc.health.v1's messages."""
    async with Linked() as shell, grpc_util.channel("127.0.0.1", shell.grpc_port) as ch:
        check = ch.unary_unary(
            "/grpc.health.v1.Health/Check",
            request_serializer=lambda b: b,
            response_deserializer=lambda b: b,
        )
        assert await check(b"", timeout=5.0) == b"\x08\x01"  # status = SERVING
        shell.link_up = False
        assert await check(b"", timeout=5.0) == b"\x08\x02"  # NOT_SERVING
        with pytest.raises(grpc.aio.AioRpcError) as err:
            await ch.unary_unary("/grpc.health.v1.Health/Watch")(b"", timeout=5.0)
        assert err.value.code() == grpc.StatusCode.UNIMPLEMENTED
