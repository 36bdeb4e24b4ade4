"""The cycle in progress, on disk: what a task that crashed mid-cycle finds when it comes back.

:class:`CycleJournal` holds the running cycle's pick record (the PickEvent it was last published
as: its id, task, object and the stage it reached), rewritten atomically when the cycle starts and
at each stage it reaches, and removed when its outcome is reported. A record still there at start
is a cycle a crash cut: :meth:`CycleJournal.leftover` returns it marked INTERRUPTED at the stage it
had reached, to be published (the gateway stores it over the running row). It stays until the next
cycle's record replaces it, so a task that dies again before then says it again (the gateway keeps
a pick's first outcome: saying it twice changes nothing).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from google.protobuf.message import DecodeError
from pickplace.v1 import task_pb2

from services.common.errors import CycleInterruptedError

log = logging.getLogger("pickplace.task.journal")


class CycleJournal:
    """One file: the serialised PickEvent of the cycle in progress (``path`` None: nothing kept)."""

    def __init__(self, path: Path | None):
        self.path = path
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)

    def write(self, event: task_pb2.PickEvent) -> None:
        """The cycle as it stands now (replaces what was there: a write cut half way leaves the old).
        A file that cannot be written is logged, never the cycle's failure: its records still go out."""
        if self.path is None:
            return
        tmp = self.path.with_suffix(".tmp")
        try:
            tmp.write_bytes(event.SerializeToString())
            os.replace(tmp, self.path)
        except OSError as exc:
            log.error("cycle journal %s not written (a crash now would leave no record): %s", self.path, exc)

    def clear(self) -> None:
        """The cycle's outcome was reported: nothing in progress."""
        if self.path is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        except OSError as exc:
            log.error("cycle journal %s not removed: %s", self.path, exc)

    def leftover(self) -> task_pb2.PickEvent | None:
        """The cycle a crash cut (marked INTERRUPTED at the stage it reached), or None."""
        if self.path is None or not self.path.exists():
            return None
        try:
            data = self.path.read_bytes()
        except OSError as exc:
            log.error("cycle journal %s unreadable, ignored: %s", self.path, exc)
            return None
        try:
            event = task_pb2.PickEvent.FromString(data)
        except DecodeError as exc:
            log.error("unreadable cycle journal %s (%d bytes), removed: %s", self.path, len(data), exc)
            self.clear()
            return None
        if not event.pick_id:
            return None
        return interrupted(event, "the task process ended")


def interrupted(event: task_pb2.PickEvent, why: str) -> task_pb2.PickEvent:
    """``event`` (a running cycle's record) as cut short by ``why`` at the stage it had reached."""
    out = task_pb2.PickEvent()
    out.CopyFrom(event)
    stage = event.stage_reached or "INIT"
    out.status = task_pb2.PICK_STATUS_INTERRUPTED
    out.success = False
    out.error_code = CycleInterruptedError.__name__
    out.failure_reason = f"{stage}: interrupted: {why}"
    return out
