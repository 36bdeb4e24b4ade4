"""The recording: every channel into MCAP files under one directory, split by size and by time.

foxglove-sdk's writer does the MCAP work (chunked, zstd/lz4, schemas and channels repeated in the
summary, chunk and message indexes, statistics); this module decides when a file ends and the next
begins, names the files, and owns the writer boundary: each file is written through
:class:`CountingFile`, which counts the bytes that reached the disk and keeps the first write error.
The SDK only prints a failed write; the error held here stops the recording (state ``FAILED``, an
event naming the file and the cause) — the cell that is being recorded goes on.

Not thread-safe by itself: one thread logs (the live view's converter thread).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import enum
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import foxglove
from foxglove.mcap import MCAPCompression, MCAPWriteOptions, MCAPWriter

from services.common.settings import McapCompression, RecordSettings
from services.record.channels import Topic, open_channels

log = logging.getLogger("pickplace.record")

PROFILE = "pickplace"  # the MCAP header's profile


class RecorderState(enum.Enum):
    RECORDING = "recording"
    FAILED = "failed"  # a write failed: nothing more is written, the cell goes on
    CLOSED = "closed"


class CountingFile:
    """The writer boundary: a seekable binary file that counts the bytes written and keeps the
    first error (the SDK's writer does not raise it to the logging call)."""

    def __init__(self, raw: BinaryIO, path: Path):
        self.raw = raw
        self.path = path
        self.bytes_written = 0  # every byte handed to the disk (the size check)
        self.size = 0  # the file's length (the writer seeks back to patch its header)
        self.error: OSError | None = None

    def write(self, data: bytes | bytearray) -> int:
        try:
            n = self.raw.write(data)
        except OSError as exc:
            if self.error is None:
                self.error = exc
            raise
        self.bytes_written += len(data)
        self.size = max(self.size, self.raw.tell())
        return n if n is not None else len(data)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self.raw.seek(offset, whence)

    def tell(self) -> int:
        return self.raw.tell()

    def flush(self) -> None:
        try:
            self.raw.flush()
        except OSError as exc:
            if self.error is None:
                self.error = exc
            raise

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.raw.close()


Opener = Callable[[Path], BinaryIO]


def open_new(path: Path) -> BinaryIO:
    """The default opener: a new file (never an existing one)."""
    return path.open("xb")


@dataclass
class FileSummary:
    path: Path
    opened_ns: int
    messages: int = 0
    bytes: int = 0
    closed_ns: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)

    def line(self) -> str:
        """The session log's line for this file."""
        secs = max(self.closed_ns - self.opened_ns, 0) / 1e9
        return f"recorded {self.path}: {self.messages} messages, {self.bytes} bytes, {secs:.1f} s"


@dataclass(frozen=True)
class RecordingStopped:
    """The event of a recording that stopped on an error: which file, and why."""

    path: Path
    reason: str


def write_options(s: RecordSettings) -> MCAPWriteOptions:
    compression = {
        McapCompression.ZSTD: MCAPCompression.Zstd,
        McapCompression.LZ4: MCAPCompression.Lz4,
        McapCompression.NONE: None,
    }[s.compression]
    return MCAPWriteOptions(
        compression=compression,
        profile=PROFILE,
        chunk_size=s.chunk_bytes,
        compression_threads=0,  # on the converter thread: no extra cores taken from the cell
    )


class Recorder:
    """MCAP files ``<prefix>_<UTC start>_<index>.mcap`` under ``directory``.

    ``attachments`` (name → (media type, bytes)), ``metadata`` and the ``latched`` messages (the robot
    description) go into every file, so each file stands alone.
    """

    def __init__(
        self,
        settings: RecordSettings,
        directory: Path,
        prefix: str = "pickplace",
        attachments: dict[str, tuple[str, bytes]] | None = None,
        metadata: dict[str, str] | None = None,
        clock_ns: Callable[[], int] = time.time_ns,
        opener: Opener = open_new,
        on_stopped: Callable[[RecordingStopped], None] | None = None,
        latched: dict[Topic, bytes] | None = None,
    ):
        self.settings = settings
        self.directory = Path(directory)
        self.prefix = prefix
        self.attachments = attachments or {}
        self.metadata = metadata or {}
        self.clock_ns = clock_ns
        self.opener = opener
        self.on_stopped = on_stopped
        self.latched = dict(latched or {})
        self.state = RecorderState.RECORDING
        self.stopped: RecordingStopped | None = None
        self.files: list[FileSummary] = []
        self._context = foxglove.Context()
        self._channels = open_channels(self._context)
        self._file: CountingFile | None = None
        self._writer: MCAPWriter | None = None
        self._current: FileSummary | None = None
        self._session = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
        self.directory.mkdir(parents=True, exist_ok=True)
        self._open_next()

    # ------------------------------------------------------------------ files
    def _next_path(self) -> Path:
        return self.directory / f"{self.prefix}_{self._session}_{len(self.files):03d}.mcap"

    def _open_next(self) -> None:
        path = self._next_path()
        now = self.clock_ns()
        try:
            raw = self.opener(path)
        except OSError as exc:
            self._fail(path, f"cannot create {path}: {exc}")
            return
        self._file = CountingFile(raw, path)
        self._current = FileSummary(path, now)
        self.files.append(self._current)
        try:
            self._writer = foxglove.open_mcap(
                self._file, context=self._context, writer_options=write_options(self.settings)
            )
            self._writer.write_metadata(
                "pickplace", {"file_index": str(len(self.files) - 1), **self.metadata}
            )
            for name, (media_type, data) in self.attachments.items():
                self._writer.attach(
                    log_time=now, create_time=now, name=name, media_type=media_type, data=data
                )
        except (RuntimeError, OSError) as exc:
            self._fail(path, self._reason(exc))
            return
        log.info("recording to %s", path)
        for topic, payload in self.latched.items():
            self._log(topic, payload, now)

    def _reason(self, exc: BaseException | None) -> str:
        err = self._file.error if self._file is not None else None
        return f"{err.strerror or err}" if err is not None else f"{exc}"

    def _close_current(self) -> bool:
        """Finish the current file (summary, indexes); False if that failed (the recording is failed)."""
        writer, f, cur = self._writer, self._file, self._current
        self._writer = None
        if writer is None or f is None or cur is None:
            return True
        try:
            writer.close()
        except (RuntimeError, OSError) as exc:
            f.close()
            self._fail(f.path, self._reason(exc))
            return False
        f.close()
        cur.bytes = f.size
        cur.closed_ns = self.clock_ns()
        log.info("%s", cur.line())
        return True

    def _fail(self, path: Path, reason: str) -> None:
        if self.state is not RecorderState.RECORDING:
            return
        self.state = RecorderState.FAILED
        if self._writer is not None:
            writer, self._writer = self._writer, None
            with contextlib.suppress(Exception):  # it has failed already; just detach it from the context
                writer.close()
        if self._file is not None:
            self._file.close()
        self.stopped = RecordingStopped(path, reason)
        log.error("recording stopped: %s: %s (the cell goes on)", path, reason)
        if self.on_stopped is not None:
            self.on_stopped(self.stopped)

    # ------------------------------------------------------------------ logging
    @property
    def recording(self) -> bool:
        return self.state is RecorderState.RECORDING

    def log(self, topic: Topic, payload: bytes, log_time_ns: int) -> None:
        """Log one message; a file past ``max_file_s`` is finished first, one past ``max_file_bytes`` after."""
        if self._current is not None and (
            self.clock_ns() - self._current.opened_ns >= self.settings.max_file_s * 1e9
        ):
            self._roll()
        if self._log(topic, payload, log_time_ns):
            f = self._file
            assert f is not None
            if f.bytes_written >= self.settings.max_file_bytes:
                self._roll()

    def _log(self, topic: Topic, payload: bytes, log_time_ns: int) -> bool:
        """Log into the current file; False when nothing is being recorded (any more)."""
        if self.state is not RecorderState.RECORDING or self._writer is None:
            return False
        self._channels[topic].log(payload, log_time=log_time_ns)
        f, cur = self._file, self._current
        assert f is not None and cur is not None
        if f.error is not None:
            self._fail(f.path, self._reason(None))
            return False
        cur.messages += 1
        cur.per_topic[topic] = cur.per_topic.get(topic, 0) + 1
        return True

    def _roll(self) -> None:
        if self.state is RecorderState.RECORDING and self._close_current():
            self._open_next()

    def close(self) -> None:
        if self.state is RecorderState.RECORDING:
            self._close_current()
            if self.state is RecorderState.RECORDING:
                self.state = RecorderState.CLOSED
        for ch in self._channels.values():
            with contextlib.suppress(Exception):
                ch.close()
