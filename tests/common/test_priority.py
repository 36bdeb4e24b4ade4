"""robot.process_nice: every thread of the cell's process at the nice value, or a warning and as it was."""

from __future__ import annotations

import subprocess
import sys

SET_EVERY_THREAD = """
import os, threading
from services.common.priority import favour_process
started = threading.Event(); end = threading.Event()
def waits():
    started.set(); end.wait()
before = threading.Thread(target=waits); before.start(); started.wait()
ok = favour_process(7, "the test")
after = threading.Thread(target=end.wait); after.start()
nices = {int(t): os.getpriority(os.PRIO_PROCESS, int(t)) for t in os.listdir("/proc/self/task")}
end.set(); before.join(); after.join()
print(ok, len(nices), sorted(set(nices.values())))
"""

REFUSED = """
import logging, os
logging.basicConfig(level=logging.WARNING, format="%(message)s")
if os.geteuid() == 0:
    os.setuid(65534)  # root may lower its nice value: as an ordinary user, which may not
from services.common.priority import favour_process, process_nice
before = process_nice()
print(favour_process(before - 5, "the test"), process_nice() == before)
"""


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)


def test_every_thread_runs_at_the_nice_value_those_before_it_and_after():
    out = _run(SET_EVERY_THREAD).stdout.split(maxsplit=2)
    assert out[0] == "True"
    assert int(out[1]) >= 3  # the main thread, one started before and one after
    assert out[2].strip() == "[7]"


def test_a_refused_nice_value_is_a_warning_naming_it_and_the_process_runs_as_it_was():
    res = _run(REFUSED)
    assert res.stdout.split() == ["False", "True"]
    assert "robot.process_nice" in res.stderr and "the OS refused" in res.stderr
    assert "CAP_SYS_NICE" in res.stderr
