"""The simulated controller's clock: sim time in every stamp, slowed (never jumped) when the machine is busy."""

import pytest

from services.sim.dobot_server import ClockPacer, SpeedWindow


def test_pacer_on_time_waits_one_period_of_wall_time():
    p = ClockPacer(0.008, speed=2.0, next_wall_s=0.0)
    assert p.after_tick(0.0) == pytest.approx(0.004)
    assert p.after_tick(0.004) == pytest.approx(0.004)
    assert p.late_ticks == 0 and p.given_up_s == 0.0


def test_pacer_makes_up_a_short_lag_then_slows_instead_of_jumping():
    p = ClockPacer(0.008, speed=1.0, next_wall_s=0.0, max_lag_s=0.05)
    # 20 ms late: ticks at once (catch up), counted late, nothing given up
    assert p.after_tick(0.028) == 0.0
    assert p.late_ticks == 1 and p.given_up_s == 0.0
    # a 1 s stall: the lag is given up, the next tick is due one period after now
    assert p.after_tick(1.0) == 0.0
    assert p.given_up_s == pytest.approx(1.0 - 0.016)
    assert p.after_tick(1.0) == pytest.approx(0.008)


def test_pacer_unpaced_never_waits():
    p = ClockPacer(0.008, speed=0.0, next_wall_s=0.0)
    assert all(p.after_tick(t) == 0.0 for t in (0.0, 5.0, 10.0))


def test_speed_window_reports_sim_per_wall():
    w = SpeedWindow(2.0, wall0_s=0.0, sim0_s=0.0)
    assert w.update(1.0, 3.0) is None
    assert w.update(2.0, 3.0) == pytest.approx(1.5)
    assert w.update(4.0, 9.0) == pytest.approx(3.0) and w.achieved == pytest.approx(3.0)
