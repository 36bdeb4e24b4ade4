"""One simulated UR controller process per test module, on its own loopback address (ur_rtde fixes
the RTDE and script ports, so each sim gets a 127.x.y.z of its own)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from services.sim.ur.controller import URControllerConfig
from services.sim.ur.process import SimSpec, URSimProcess
from services.sim.ur.server import free_loopback_host

FAST = URControllerConfig(power_on_s=0.05, brake_release_s=0.05, unlock_delay_s=0.2)


def start_sim(model: str = "ur5e", config: URControllerConfig = FAST) -> URSimProcess:
    return URSimProcess(SimSpec(model, free_loopback_host(), config))


@pytest.fixture(scope="module")
def ur_sim() -> Iterator[URSimProcess]:
    with start_sim() as sim:
        yield sim
