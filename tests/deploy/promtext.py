"""Metric names in Prometheus text exposition and in Grafana dashboard queries."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
DASHBOARD_DIR = REPO / "deploy" / "grafana" / "dashboards"
SELECTOR = re.compile(r"([a-zA-Z_:][a-zA-Z0-9_:]*)\s*\{")
NAME = re.compile(r"^([a-zA-Z_:][a-zA-Z0-9_:]*)")
FAMILY_SAMPLES = {
    "counter": ("_total",),
    "gauge": ("",),
    "histogram": ("_bucket", "_sum", "_count"),
    "summary": ("", "_sum", "_count"),
}


def exposition_names(text: str) -> set[str]:
    """Every sample name in a ``/metrics`` page, and the sample names of every declared (``# TYPE``)
    family: a labelled family with no series yet (no e-stop so far) is still exported."""
    names: set[str] = set()
    for line in text.splitlines():
        if line.startswith("# TYPE "):
            _, _, name, kind = line.split()[:4]
            if kind == "counter":
                name = name.removesuffix("_total")
            names.update(f"{name}{suffix}" for suffix in FAMILY_SAMPLES.get(kind, ("",)))
        elif line and not line.startswith("#"):
            m = NAME.match(line)
            if m:
                names.add(m.group(1))
    return names


def exposition_samples(text: str, name: str) -> list[float]:
    return [
        float(line.rsplit(" ", 1)[1])
        for line in text.splitlines()
        if line.startswith(name + "{") or line.startswith(name + " ")
    ]


def dashboards() -> dict[str, dict[str, Any]]:
    return {p.name: json.loads(p.read_text()) for p in sorted(DASHBOARD_DIR.glob("*.json"))}


def panels(dashboard: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    for p in dashboard.get("panels", []):
        out.append(p)
        out.extend(p.get("panels", []))  # collapsed rows hold their panels
    return out


def query_exprs(dashboard: dict[str, Any]) -> list[str]:
    return [t["expr"] for p in panels(dashboard) for t in p.get("targets", []) if "expr" in t]


def queried_metrics(expr: str) -> set[str]:
    """Metric names an expression selects. The dashboards write every selector as ``name{...}``."""
    return set(SELECTOR.findall(expr))
