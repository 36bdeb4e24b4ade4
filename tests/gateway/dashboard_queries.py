"""Grafana's queries against an exporter's series: which selectors would find nothing.

Each selector ``name{label=~"re", label="v"}`` of every panel, with ``$cell`` and ``$robot`` set to
the cell's values, must match at least one sample of the ``/metrics`` text (the same matching
Prometheus does: ``=`` exact, ``=~`` a full regular-expression match, ``!=`` / ``!~`` negated).
"""

from __future__ import annotations

import re

from tests.deploy.promtext import dashboards, query_exprs

SELECTOR = re.compile(r"([a-zA-Z_:][a-zA-Z0-9_:]*)\s*\{([^}]*)\}")
MATCHER = re.compile(r'\s*([a-zA-Z_][a-zA-Z0-9_]*)\s*(=~|!~|!=|=)\s*"((?:[^"\\]|\\.)*)"\s*')
SAMPLE = re.compile(r"^([a-zA-Z_:][a-zA-Z0-9_:]*)(?:\{(.*)\})?\s+\S+")
LABEL = re.compile(r'([a-zA-Z_][a-zA-Z0-9_]*)="((?:[^"\\]|\\.)*)"')


def samples(text: str) -> list[tuple[str, dict[str, str]]]:
    out = []
    for line in text.splitlines():
        if line.startswith("#") or not line.strip():
            continue
        m = SAMPLE.match(line)
        if m:
            out.append((m.group(1), dict(LABEL.findall(m.group(2) or ""))))
    return out


def _matches(labels: dict[str, str], matchers: list[tuple[str, str, str]]) -> bool:
    for name, op, value in matchers:
        have = labels.get(name, "")
        ok = {
            "=": have == value,
            "!=": have != value,
            "=~": re.fullmatch(value, have) is not None,
            "!~": re.fullmatch(value, have) is None,
        }[op]
        if not ok:
            return False
    return True


def empty_selectors(text: str, variables: dict[str, str]) -> list[str]:
    """Every dashboard selector (after substituting ``variables``) that no sample of ``text`` matches."""
    have = samples(text)
    missing = []
    for board in dashboards().values():
        for expr in query_exprs(board):
            for var, value in variables.items():
                expr = expr.replace(f"${var}", value)
            for name, inner in SELECTOR.findall(expr):
                matchers = [m.groups() for m in MATCHER.finditer(inner)]
                if not any(n == name and _matches(lab, matchers) for n, lab in have):
                    missing.append(f"{name}{{{inner}}}")
    return sorted(set(missing))
