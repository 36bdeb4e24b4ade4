"""The cell's processes before other work on the machine (``robot.process_nice``).

The arm's controller runs on its own hardware; the PC that feeds it shares its cores with whatever else
runs there. A stream of ServoJ targets, a reply the task waits on, a frame the arm waits to be seen in:
each is late by as long as the scheduler gives the cores to other jobs, and the controller's clock runs
on meanwhile. Robot drivers ask the OS to schedule their control loop first (ur_rtde and ros2_control
ask for real-time priority, and warn and go on when it is refused); the cell asks for a negative nice
value for every thread of its process, which keeps the machine responsive to everyone else.

On Linux the nice value is each thread's own (a thread takes its creator's when it starts), so every
thread running now is set, and those started later inherit it.
"""

from __future__ import annotations

import logging
import os

log = logging.getLogger("pickplace.priority")


def process_nice() -> int:
    """The nice value of the calling thread (the process's, unless set per thread)."""
    return os.getpriority(os.PRIO_PROCESS, 0)


def _threads() -> list[int]:
    try:
        return sorted(int(tid) for tid in os.listdir("/proc/self/task"))
    except OSError:  # no /proc: the calling thread, which the threads started later inherit from
        return [0]


def favour_process(nice: int | None, what: str) -> bool:
    """Run every thread of this process at ``nice`` (None: leave it as it is). True when it runs there.
    A value below the present one needs CAP_SYS_NICE (root has it; a container is given it with
    ``cap_add: [SYS_NICE]``); when the OS refuses, a warning says so and the process runs as it was."""
    if nice is None:
        return False
    for tid in _threads():
        try:
            os.setpriority(os.PRIO_PROCESS, tid, nice)
        except ProcessLookupError:  # the thread ended meanwhile
            continue
        except PermissionError as exc:
            log.warning(
                "%s runs at nice %d, not at robot.process_nice %d: the OS refused (%s; a value below "
                "the present one needs CAP_SYS_NICE). Its cycle will vary with the machine's load",
                what,
                process_nice(),
                nice,
                exc.strerror,
            )
            return False
    log.info("%s runs at nice %d", what, nice)
    return True
