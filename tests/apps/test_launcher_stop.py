"""The launcher stops the processes that publish before the ones that store what they publish."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

from services.apps.launcher import Launcher
from services.apps.topology import RECORD, LocalPorts, ProcessSpec
from services.common.settings import load_settings

# on SIGTERM: append the name to the shared file, then exit
CHILD = """
import signal, sys, time
name, path = sys.argv[1], sys.argv[2]
def stop(*_):
    with open(path, "a") as f:
        f.write(name + "\\n")
    sys.exit(0)
signal.signal(signal.SIGTERM, stop)
print("ready", flush=True)
while True:
    time.sleep(1)
"""


async def test_the_gateway_and_recorder_stop_after_every_publisher(tmp_path: Path) -> None:
    names = ["sim-dobot", "robot", "task", "gateway", RECORD]
    order = tmp_path / "order.txt"
    launcher = Launcher(
        load_settings("sim"),
        [ProcessSpec(n, (), {}) for n in names],
        LocalPorts.free(),
        log_dir=tmp_path,
        stop_grace_s=30.0,
    )
    for name in names:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-c", CHILD, name, str(order), stdout=asyncio.subprocess.PIPE
        )
        assert proc.stdout is not None
        assert await proc.stdout.readline() == b"ready\n"  # its handler is installed
        launcher.children[name].proc = proc
    await launcher.stop()
    stopped = (await asyncio.to_thread(order.read_text)).split()
    assert sorted(stopped) == sorted(names)  # each stopped on SIGTERM, none killed
    assert set(stopped[:3]) == {"sim-dobot", "robot", "task"}
    assert set(stopped[3:]) == {"gateway", RECORD}
    assert all(launcher.children[n].proc.returncode == 0 for n in names)  # type: ignore[union-attr]
