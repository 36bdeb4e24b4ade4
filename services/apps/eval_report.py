"""What ``pickplace eval`` says: the success rate with its 95 % Wilson interval, the sensitivity of success
to each randomized parameter (success per bin of its range), the console tables and the JSON file.

Pure over plain values except :func:`print_report` (rich) and :func:`write_report` (a file).
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from rich.console import Console
from rich.table import Table

if TYPE_CHECKING:
    from services.apps.evaluation import EvalReport

Z_95 = 1.959963984540054  # two-sided 95 % normal quantile
SENSITIVITY_BINS = 4
WEAK_BIN_RATE = 0.98  # issue 19's target: no parameter bin below 98 %


class BinStat(TypedDict):
    lo: float
    hi: float
    trials: int
    successes: int
    rate: float | None
    wilson_low: float | None


def wilson_interval(successes: int, trials: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default); (0, 1) without trials."""
    if trials < 0 or not 0 <= successes <= trials:
        raise ValueError(f"need 0 <= successes <= trials, got {successes} of {trials}")
    if trials == 0:
        return 0.0, 1.0
    n, p = float(trials), successes / trials
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    lo = 0.0 if successes == 0 else max(0.0, centre - half)  # exact at the ends (no rounding past p)
    hi = 1.0 if successes == trials else min(1.0, centre + half)
    return lo, hi


def sensitivity(
    outcomes: Iterable[tuple[Mapping[str, float], bool]],
    ranges: Mapping[str, tuple[float, float]],
    bins: int = SENSITIVITY_BINS,
) -> dict[str, list[BinStat]]:
    """Success per equal-width bin of each parameter's configured range (values outside it count in the
    edge bins). ``outcomes``: (the trial's randomization record, its success) of the trials that ran."""
    if bins < 1:
        raise ValueError(f"bins must be >= 1, got {bins}")
    counts = {k: [[0, 0] for _ in range(bins)] for k in ranges}
    for record, ok in outcomes:
        for key, (lo, hi) in ranges.items():
            if key not in record:
                continue
            width = (hi - lo) / bins
            i = 0 if width <= 0 else min(bins - 1, max(0, math.floor((record[key] - lo) / width)))
            counts[key][i][0] += 1
            counts[key][i][1] += int(ok)
    table: dict[str, list[BinStat]] = {}
    for key, (lo, hi) in ranges.items():
        width = (hi - lo) / bins
        row: list[BinStat] = []
        for i, (n, k) in enumerate(counts[key]):
            row.append(
                {
                    "lo": round(lo + i * width, 6),
                    "hi": round(lo + (i + 1) * width, 6),
                    "trials": n,
                    "successes": k,
                    "rate": k / n if n else None,
                    "wilson_low": wilson_interval(k, n)[0] if n else None,
                }
            )
        table[key] = row
    return table


def worst_bin_rate(row: list[BinStat]) -> float:
    rates = [b["rate"] for b in row if b["rate"] is not None]
    return min(rates) if rates else 1.0


def _p95(xs: list[float]) -> float | None:
    if not xs:
        return None
    s = sorted(xs)
    return s[min(len(s) - 1, round(0.95 * (len(s) - 1)))]


def _fmt_edge(x: float) -> str:
    return f"{x:.3g}"


def print_sensitivity(table: Mapping[str, list[BinStat]], console: Console, title: str) -> None:
    """One row per parameter, weakest first: its range, then successes/trials per equal-width bin of it
    (low to high); a bin below 98 % in red."""
    if not table:
        return
    bins = max(len(r) for r in table.values())
    t = Table(title=title)
    t.add_column("parameter", no_wrap=True)
    t.add_column("range (bins of equal width)", no_wrap=True)
    for i in range(bins):
        t.add_column(f"bin {i + 1}", justify="right", no_wrap=True)
    t.add_column("worst", justify="right", no_wrap=True)
    for key, row in sorted(table.items(), key=lambda kv: (worst_bin_rate(kv[1]), kv[0])):
        cells = []
        for b in row:
            if b["rate"] is None:
                cells.append("-")
                continue
            text = f"{b['successes']}/{b['trials']}"
            cells.append(f"[red]{text}[/red]" if b["rate"] < WEAK_BIN_RATE else text)
        span = f"{_fmt_edge(row[0]['lo'])} … {_fmt_edge(row[-1]['hi'])}"
        t.add_row(key, span, *cells, f"{100 * worst_bin_rate(row):.1f} %")
    console.print(t)


def print_report(report: EvalReport, console: Console) -> None:
    from services.apps.evaluation import SETTLE_S

    s = report.summary()
    world = "randomized worlds" if s["randomized"] else "the nominal world"
    t = Table(title=f"pickplace eval — {report.task}, {s['trials']} trials from seed {report.seed}, {world}")
    t.add_column("metric")
    t.add_column("value", justify="right")
    t.add_row(
        "success rate (ground truth)", f"{100 * report.success_rate:.1f} % ({report.successes}/{s['trials']})"
    )
    lo, hi = s["success_ci95"]
    t.add_row("success 95 % interval (Wilson)", f"{100 * lo:.1f} % … {100 * hi:.1f} %")
    for label, v in (
        ("cycle time median (controller clock)", s["cycle_time_median_s"]),
        ("cycle time p95 (controller clock)", s["cycle_time_p95_s"]),
        ("cycle time median on a 1× cell (this machine's compute)", s["cycle_time_1x_median_s"]),
        ("compute (detect + plan) median, wall time", s["compute_wall_median_s"]),
        (
            "bound (ruckig, the executed waypoints and stops + touch-down pace + gripper) median",
            s["bound_median_s"],
        ),
        ("of the bound: the touch-downs' pace beyond the joints' time (median)", s["bound_pace_median_s"]),
    ):
        t.add_row(label, "-" if v is None else f"{v:.2f} s")
    share = s["compute_share_of_cycle"]
    t.add_row("compute share of a 1× cycle", "-" if share is None else f"{100 * share:.1f} %")
    camera, own = s["camera_wall_median_s"], s["cell_compute_share_of_cycle"]
    if camera is not None and own is not None and camera > 0:
        t.add_row(
            "of the compute: the twin camera's frames (median) / the rest's share",
            f"{camera:.2f} s / {100 * own:.1f} %",
        )
    ratio, ratio95 = s["bound_ratio_median"], s["bound_ratio_p95"]
    if ratio is not None and ratio95 is not None:
        t.add_row("measured / bound (median / p95)", f"{ratio:.2f} / {ratio95:.2f}")
    if (unjerked := s["accel_limited_bound_ratio_median"]) is not None:
        t.add_row("measured / bound without the jerk limit (median)", f"{unjerked:.2f}")
    tilts = [r.tilt_before_release_deg for r in report.results if r.tilt_before_release_deg is not None]
    if tilts:
        t.add_row(
            "tilt before release (median / max)", f"{statistics.median(tilts):.2f}° / {max(tilts):.2f}°"
        )
    slow = sum(r.settle_s > SETTLE_S for r in report.results)
    if slow:
        t.add_row(f"judged after more than {SETTLE_S:.0f} s settling", str(slow))
    stages = s["stage_median_s"]
    if stages:
        t.add_row("median per state (controller clock)", " ".join(f"{k} {v:.2f}" for k, v in stages.items()))
    if s["load"]:
        t.add_row(
            "load (busy processes beside the cell)",
            f"{s['load']} at nice {s['load_nice']}, the cell at nice {s['cell_nice']}",
        )
    if s["sim_speed_achieved"] is not None:
        t.add_row(
            "sim speed achieved (late ticks)", f"{s['sim_speed_achieved']:.2f}× ({s['sim_late_ticks']})"
        )
    if s["harness_errors"]:
        t.add_row("harness errors", str(s["harness_errors"]))
    t.add_row("wall time", f"{report.wall_time_s:.0f} s")
    for reason, n in s["failures"].items():
        t.add_row(f"failed at {reason}", str(n))
    console.print(t)
    print_sensitivity(
        s["sensitivity"],
        console,
        f"success per bin of each randomized parameter (weakest first; red below {100 * WEAK_BIN_RATE:.0f} %)",
    )


def write_report(report: EvalReport, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(report.to_json())
