"""Whether a cycle runs, from the task's status (pure; the vision and sim tests cover the bus)."""

from __future__ import annotations

from services.common.cycle_watch import CycleWatch


def test_active_from_a_status_saying_so_until_one_says_otherwise() -> None:
    w = CycleWatch(stale_s=3.0)
    assert not w.active(0.0)  # no status yet: the loop runs
    w.on_status(True, 10.0)
    assert w.active(10.0) and w.active(12.9)
    w.on_status(True, 12.0)
    assert w.active(14.9)
    w.on_status(False, 13.0)
    assert not w.active(13.0)


def test_a_task_fallen_silent_mid_cycle_does_not_pause_the_loop_for_good() -> None:
    w = CycleWatch(stale_s=3.0)
    w.on_status(True, 10.0)
    assert w.active(13.0)
    assert not w.active(13.01)


def test_live_during_cycle_keeps_periodic_work_going() -> None:
    w = CycleWatch(stale_s=3.0)
    w.on_status(True, 10.0)
    assert w.gives_way(11.0, live_during_cycle=False)
    assert not w.gives_way(11.0, live_during_cycle=True)
    assert not w.gives_way(14.0, live_during_cycle=False)  # stale
