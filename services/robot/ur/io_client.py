"""The UR's digital outputs over RTDE, with the house codec (:mod:`services.rtde`) on asyncio.

ur_rtde's RTDEIOInterface would do the same, but it cannot be let go once its connection was lost:
its disconnect throws (the peer is gone) and leaves it "connected", and its C++ destructor then
disconnects again and throws out of a destructor, which ends the whole process (std::terminate) —
found by pulling the simulated controller's cable (tests/robot/ur). Writing the four RTDE input
fields it writes needs no C++: one input recipe, one data package per change.
"""

from __future__ import annotations

import asyncio
import contextlib

from services.common.errors import RobotCommunicationError
from services.rtde import codec
from services.rtde.codes import MessageType
from services.rtde.fields import input_type

RTDE_PORT = 30004
FIELDS = (
    "standard_digital_output_mask",
    "standard_digital_output",
    "tool_digital_output_mask",
    "tool_digital_output",
)


class RTDEOutputs:
    def __init__(self, host: str, port: int = RTDE_PORT, timeout_s: float = 2.0):
        self.host, self.port, self.timeout_s = host, port, timeout_s
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._recipe: codec.Recipe | None = None
        self._framer = codec.Framer()

    async def _reply(self, msg_type: int) -> codec.Package:
        assert self._reader is not None
        while True:
            data = await self._reader.read(65536)
            if not data:
                raise RobotCommunicationError(f"UR {self.host}: RTDE closed during setup")
            for pkg in self._framer.feed(data):
                if pkg.type == msg_type:
                    return pkg

    async def connect(self) -> None:
        await self.close()
        try:
            async with asyncio.timeout(self.timeout_s):
                self._reader, self._writer = await asyncio.open_connection(self.host, self.port)
                self._framer = codec.Framer()
                self._writer.write(codec.request_protocol_version())
                if (await self._reply(MessageType.REQUEST_PROTOCOL_VERSION)).payload[:1] != b"\x01":
                    raise RobotCommunicationError(f"UR {self.host}: RTDE protocol version 2 refused")
                self._writer.write(codec.setup_inputs_request(FIELDS))
                rid, words = codec.parse_setup_reply(
                    (await self._reply(MessageType.CONTROL_PACKAGE_SETUP_INPUTS)).payload
                )
        except (OSError, TimeoutError) as exc:
            await self.close()
            raise RobotCommunicationError(f"UR {self.host}: RTDE outputs not reachable: {exc}") from exc
        if rid == 0:
            await self.close()
            raise RobotCommunicationError(
                f"UR {self.host}: output recipe refused: {dict(zip(FIELDS, words, strict=False))}"
            )
        types = tuple(t for t in (input_type(n) for n in FIELDS) if t is not None)
        self._recipe = codec.Recipe(rid, FIELDS, types)
        self._drain = asyncio.get_running_loop().create_task(self._discard(), name=f"ur-io-{self.host}")

    async def _discard(self) -> None:
        """Text messages the controller may send on this connection: read and dropped."""
        assert self._reader is not None
        with contextlib.suppress(OSError):
            while await self._reader.read(65536):
                pass

    async def set(self, index: int, on: bool, tool: bool) -> None:
        if self._writer is None or self._recipe is None or self._writer.is_closing():
            await self.connect()
        assert self._writer is not None and self._recipe is not None
        mask = 1 << index
        values = dict.fromkeys(FIELDS, 0)
        prefix = "tool" if tool else "standard"
        values[f"{prefix}_digital_output_mask"] = mask
        values[f"{prefix}_digital_output"] = mask if on else 0
        try:
            self._writer.write(codec.pack(MessageType.DATA_PACKAGE, self._recipe.pack(values)))
            await self._writer.drain()
        except OSError as exc:
            await self.close()
            raise RobotCommunicationError(f"UR {self.host}: digital output not sent: {exc}") from exc

    async def close(self) -> None:
        writer, self._writer, self._recipe = self._writer, None, None
        drain = getattr(self, "_drain", None)
        if drain is not None:
            drain.cancel()
        if writer is not None:
            writer.close()
            with contextlib.suppress(Exception):
                await writer.wait_closed()
