"""Benchmark of the physics twin: real-time factor, ms per RGB-D frame, pick-and-stand trial time, and
the cost of a randomized world (what `pickplace eval` builds for every trial).

Run alone with ``python -m bench.bench_twin`` (``python -m bench`` calls ``main()``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import time
from typing import Any

import numpy as np

from services.common.settings import Settings, load_settings
from services.sim.twin import create_twin_engine
from services.sim.twin.camera import TwinCamera
from services.sim.twin.model import build_world
from services.sim.twin.trial import TICK_S, run_rod_stand_trial

HOME = np.deg2rad([0.0, 0.0, 90.0, 0.0, -90.0, 0.0])


def _settings(scene: dict[str, Any] | None = None, physics: dict[str, Any] | None = None) -> Settings:
    return load_settings(
        "sim",
        overrides={
            "sim": {"twin": {"scene": scene or {}, "physics": physics or {}}},
            "logging": {"file": None},
        },
    )


def real_time_factor(sim_seconds: float = 20.0) -> tuple[float, float]:
    """Arm sweeping its joints sinusoidally over the full scene, 8 ms ticks. → (RTF, µs per tick)."""
    engine = create_twin_engine(_settings(), seed=0)
    amp = np.deg2rad([30.0, 20.0, 20.0, 30.0, 30.0, 60.0])
    w = 2 * np.pi * 0.25
    n = round(sim_seconds / TICK_S)
    t0 = time.perf_counter()
    for k in range(1, n + 1):
        t = k * TICK_S
        engine.step(TICK_S, HOME + amp * np.sin(w * t), amp * w * np.cos(w * t), -amp * w * w * np.sin(w * t))
    wall = time.perf_counter() - t0
    return sim_seconds / wall, wall / n * 1e6


def frame_times(n: int = 20) -> dict[str, float]:
    engine = create_twin_engine(_settings(), seed=0)
    out: dict[str, float] = {}
    for noise in (False, True):
        cam = TwinCamera(engine, seed=0, noise=noise)
        t0 = time.perf_counter()
        cam.capture()
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        for _ in range(n):
            cam.capture()
        out[f"noise={'on' if noise else 'off'}"] = (time.perf_counter() - t0) / n * 1000
        out[f"first_frame_noise={'on' if noise else 'off'}"] = first * 1000
        cam.close()
    return out


def randomized_world_times(n: int = 10) -> dict[str, float]:
    """ms to build (MJCF + compile + gains) a nominal and a randomized world, and per noisy frame in one."""
    nominal = _settings()
    rnd = nominal.sim.twin.randomization.model_copy(update={"enabled": True})
    randomized = nominal.model_copy(
        update={
            "sim": nominal.sim.model_copy(
                update={"twin": nominal.sim.twin.model_copy(update={"randomization": rnd})}
            )
        }
    )
    out: dict[str, float] = {}
    for label, s in (("nominal", nominal), ("randomized", randomized)):
        t0 = time.perf_counter()
        for seed in range(n):
            build_world(s, seed)
        out[f"build_{label}_ms"] = (time.perf_counter() - t0) / n * 1000
    engine = create_twin_engine(randomized, seed=0)
    cam = TwinCamera(engine, seed=0)
    cam.capture()
    t0 = time.perf_counter()
    for _ in range(n):
        cam.capture()
    out["frame_randomized_ms"] = (time.perf_counter() - t0) / n * 1000
    cam.close()
    return out


def trials(seeds: range, physics: dict[str, Any] | None = None) -> dict[str, float]:
    settings = _settings({"cubes": [], "obstacle": False}, physics)
    ok, walls, sims, slips_mm, slips_deg, tilt_before = 0, [], [], [], [], []
    unreachable = 0
    for seed in seeds:
        engine = create_twin_engine(settings, seed)
        t0 = time.perf_counter()
        r = run_rod_stand_trial(engine)
        walls.append(time.perf_counter() - t0)
        if r.error and "IK" in r.error:
            unreachable += 1
            continue
        sims.append(r.sim_time_s)
        ok += int(r.success)
        slips_mm.append(r.metrics.slip_mm)
        slips_deg.append(r.metrics.slip_deg)
        if r.metrics.tilt_before_place_deg is not None:
            tilt_before.append(r.metrics.tilt_before_place_deg)
    run = len(sims)
    return {
        "trials": run,
        "success": ok,
        "unreachable_for_script": unreachable,
        "wall_s_mean": float(np.mean(walls)),
        "sim_s_mean": float(np.mean(sims)) if sims else float("nan"),
        "slip_mm_max": float(np.max(slips_mm)) if slips_mm else float("nan"),
        "slip_deg_max": float(np.max(slips_deg)) if slips_deg else float("nan"),
        "tilt_before_place_deg_max": float(np.max(tilt_before)) if tilt_before else float("nan"),
    }


def main() -> None:
    print("== twin: physics ==")
    rtf, us = real_time_factor()
    print(f"real-time factor {rtf:.1f}x  ({us:.0f} µs per 8 ms control tick, full scene, arm moving)")
    print("== twin: simulated RealSense 640x480 (colour + depth + segmentation passes) ==")
    for k, v in frame_times().items():
        print(f"{k:24s} {v:7.1f} ms")
    print("== twin: per-trial randomized world (sim.twin.randomization) ==")
    for k, v in randomized_world_times().items():
        print(f"{k:24s} {v:7.1f} ms")
    print("== twin: scripted pick-lift-turn-stand trial (rod only, perfect perception) ==")
    for label, physics in (("default (impratio 10)", None), ("impratio 1", {"impratio": 1.0})):
        r = trials(range(12), physics)
        print(
            f"{label:22s} success {r['success']}/{r['trials']} (script unreachable: "
            f"{r['unreachable_for_script']}), wall {r['wall_s_mean']:.2f} s for {r['sim_s_mean']:.1f} s sim, "
            f"slip max {r['slip_mm_max']:.2f} mm / {r['slip_deg_max']:.2f}°, "
            f"tilt before place max {r['tilt_before_place_deg_max']:.2f}°"
        )


if __name__ == "__main__":
    main()
