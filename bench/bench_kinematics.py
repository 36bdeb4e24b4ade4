"""IK figures: the closed form (issue 11, item 10: speed, public/raw ratio, exactness on the URDF)
and the numerical IK (issue 3: ≥ 99.9 % success, median ≤ 150 µs from a cold seed).

For each robot, 10,000 random in-limit configurations (seeded) and their flange poses from
pinocchio on ``config/robots/<name>.urdf``:

- single pose: ``analytic.ik_solutions`` on the URDF model (the raw solver: every branch,
  wrapped, no limits), µs per pose;
- batched: ``analytic.ik_all`` on all poses at once, µs per pose;
- public/raw: ``Kinematics.ik_analytic`` (tool pose in, pose check, seed, limits, turn nearest
  the seed, sorted array out) over the raw solver on the same poses;
- exactness: the worst pose error of every returned solution, by pinocchio on the URDF, and how
  often the original configuration is among the solutions (1e-9 rad, modulo full turns).

Times: rounds of raw and public alternate over the same poses and the best round of each counts,
so that the ratio compares like with like on a shared machine.

Targets: every solution exact to 1e-9 m / 1e-9 rad, the original configuration among the
solutions 100 %, public ≤ 1.5 × raw; no slower than before (analytic 25.6 µs single,
9.4 µs batched per pose on the reference machine).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from services.common.errors import RobotError
from services.kinematics import analytic
from services.kinematics.analytic import KinematicModel
from services.kinematics.model import Kinematics, load_arm
from services.kinematics.urdf import flange_link

ROBOTS = ("nova5", "ur5e", "ur3")
URDF = KinematicModel.URDF
EXACT = 1e-9  # m and rad: what every solution must reproduce its pose to, on the URDF
SAME_RAD = 1e-9  # a solution is the original configuration when within this (modulo full turns)


def random_configurations(kin: Kinematics, rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform within the joint limits (at most two turns either side), (n, 6)."""
    lo = np.maximum(kin.limits.lower, -2 * np.pi)
    hi = np.minimum(kin.limits.upper, 2 * np.pi)
    return rng.uniform(lo, hi, (n, kin.dof))


def pose_error(kin: Kinematics, q: np.ndarray, T: np.ndarray, frame: str) -> tuple[float, float]:
    """(position m, rotation rad) of pinocchio's FK of ``frame`` at q against T."""
    Tq = kin.fk(q, frame)
    dR = Tq[:3, :3].T @ T[:3, :3]
    # atan2(sin, cos) of the angle: accurate for tiny angles, where arccos of the trace is not
    sin = 0.5 * float(np.linalg.norm([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]]))
    angle = float(np.arctan2(sin, (np.trace(dR) - 1.0) / 2.0))
    return float(np.linalg.norm(Tq[:3, 3] - T[:3, 3])), angle


def exactness(
    kin: Kinematics, qs: np.ndarray, Ts: list[np.ndarray], frame: str
) -> tuple[float, float, int, int, int]:
    """(worst position m, worst rotation rad, solutions, exact solutions, poses whose original
    configuration is among the solutions) of ``analytic.ik_solutions`` on the URDF."""
    worst_p = worst_r = 0.0
    total = exact = recovered = 0
    for q0, T in zip(qs, Ts, strict=True):
        sols = analytic.ik_solutions(kin.spec, T, model=URDF)
        total += len(sols)
        found = False
        for q in sols:
            p, r = pose_error(kin, np.asarray(q), T, frame)
            worst_p, worst_r = max(worst_p, p), max(worst_r, r)
            exact += p <= EXACT and r <= EXACT
            found = found or bool(
                np.max(np.abs((np.asarray(q) - q0 + np.pi) % (2 * np.pi) - np.pi)) < SAME_RAD
            )
        recovered += found
    return worst_p, worst_r, total, exact, recovered


def _best_of(rounds: int, *loops: Callable[[], None]) -> list[float]:
    """Best wall time (s) of each loop over ``rounds`` alternating rounds."""
    best = [float("inf")] * len(loops)
    for _ in range(rounds):
        for i, loop in enumerate(loops):
            t0 = time.perf_counter()
            loop()
            best[i] = min(best[i], time.perf_counter() - t0)
    return best


def bench_ik(n: int = 10_000, rounds: int = 5) -> None:
    print(
        f"closed-form IK on the URDF, {n} random in-limit configurations per robot "
        f"(times: best of {rounds} alternating rounds)"
    )
    for name in ROBOTS:
        _bench_robot(name, n, rounds)


def _bench_robot(name: str, n: int, rounds: int) -> None:
    kin = Kinematics(load_arm(name))
    spec, frame = kin.spec, flange_link(kin.spec)
    qs = random_configurations(kin, np.random.default_rng(0), n)
    T_flange = [kin.fk(q, frame) for q in qs]
    T_tool = [kin.fk(q) for q in qs]
    seeds = [q.copy() for q in qs]
    batch = np.stack(T_flange)

    def raw() -> None:
        for T in T_flange:
            analytic.ik_solutions(spec, T, model=URDF)

    def public() -> None:
        for T, seed in zip(T_tool, seeds, strict=True):
            kin.ik_analytic(T, seed)

    def batched() -> None:
        analytic.ik_all(spec, batch, model=URDF)

    raw(), public()  # warm up
    t_raw, t_public, t_batch = _best_of(rounds, raw, public, batched)
    worst_p, worst_r, total, exact, recovered = exactness(kin, qs, T_flange, frame)
    _, valid = analytic.ik_all(spec, batch, model=URDF)
    print(
        f"  {name:5s} single {t_raw / n * 1e6:.1f} µs, batched {t_batch / n * 1e6:.2f} µs/pose, "
        f"public {t_public / n * 1e6:.1f} µs = {t_public / t_raw:.2f}× raw; "
        f"{total / n:.2f} solutions/pose (batch agrees: {int(valid.sum()) == total}), "
        f"{exact}/{total} exact to 1e-9 on the URDF (worst {worst_p:.1e} m, {worst_r:.1e} rad), "
        f"original among them {recovered / n:.2%}"
    )


def bench_numeric(n: int = 2000) -> None:
    print(
        f"numerical IK (LM + restarts) of the tool tip from a cold seed, {n} random reachable poses per robot"
    )
    for name in ROBOTS:
        kin = Kinematics(load_arm(name))
        rng = np.random.default_rng(1)
        cold = np.deg2rad([0, 0, 90, 0, -90, 0]) if name == "nova5" else np.deg2rad([0, -90, 90, -90, -90, 0])
        Ts = [kin.fk(q) for q in random_configurations(kin, rng, n)]
        restart_rng = np.random.default_rng(2)
        wall, cpu, ok = [], [], 0
        for T in Ts:
            w0, c0 = time.perf_counter(), time.process_time()
            try:
                q = kin.ik_numeric(T, cold, rng=restart_rng)
            except RobotError:
                q = None
            wall.append(time.perf_counter() - w0)
            cpu.append(time.process_time() - c0)
            if q is not None and kin.pose_error(q, T)[0] < 1e-6:
                ok += 1
        print(
            f"  {name:5s} success {ok / n:.2%}; {_stats_us(wall)} (CPU median {np.median(cpu) * 1e6:.1f} µs)"
        )


def _stats_us(xs: list[float]) -> str:
    a = np.asarray(xs) * 1e6
    return f"median {np.median(a):.1f} µs, mean {a.mean():.1f} µs, p95 {np.percentile(a, 95):.1f} µs"


def main() -> None:
    bench_ik()
    bench_numeric()


if __name__ == "__main__":
    main()
