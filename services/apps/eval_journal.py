"""The trial journal of a ``pickplace eval`` run: one JSON line per finished trial, written as it ends.

A long evaluation (1,000 trials is hours on two cores) must lose nothing when it is interrupted: the
journal beside the report (``<report>.trials.jsonl``) holds the header of the run (what it evaluates)
and every finished trial; ``--resume`` reads it back, skips those trials and appends the rest. Every
trial's world and scene come from its own seed, so a resumed run judges the same trials an unbroken one
would.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from services.common.errors import ConfigurationError

if TYPE_CHECKING:
    from services.apps.evaluation import TrialResult

JOURNAL_SUFFIX = ".trials.jsonl"
HEADER_KEYS = ("task", "seed", "trials", "randomized", "calibration_error", "robot")


def journal_path(report_path: Path) -> Path:
    return report_path.with_name(report_path.name + JOURNAL_SUFFIX)


class TrialJournal:
    """Appends each finished trial to the journal and flushes it to disk before the next trial starts."""

    def __init__(self, path: Path, header: Mapping[str, Any], done: list[TrialResult]) -> None:
        self.path = path
        self.header = dict(header)
        self.done = done  # trials read back from an earlier run of the same evaluation
        self._file: IO[str] | None = None

    @classmethod
    def open(cls, path: Path, header: Mapping[str, Any], resume: bool) -> TrialJournal:
        """A journal for the run ``header`` describes. ``resume``: continue the one at ``path`` (it must
        describe the same run); otherwise start afresh (an earlier journal there is replaced)."""
        done: list[TrialResult] = []
        if resume and path.exists():
            done = read_journal(path, header)
        journal = cls(path, header, done)
        path.parent.mkdir(parents=True, exist_ok=True)
        if done:
            journal._file = path.open("a", encoding="utf-8")
        else:
            journal._file = path.open("w", encoding="utf-8")
            journal._write({"header": journal.header})
        return journal

    def done_by_seed(self) -> dict[int, TrialResult]:
        return {r.seed: r for r in self.done}

    def append(self, result: TrialResult) -> None:
        self._write({"trial": dataclasses.asdict(result)})

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def _write(self, record: dict[str, Any]) -> None:
        assert self._file is not None, "journal is closed"
        self._file.write(json.dumps(record) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())


def read_journal(path: Path, header: Mapping[str, Any]) -> list[TrialResult]:
    """The finished trials of the journal at ``path``, which must describe the run ``header`` does.
    A last line cut short by the interruption is dropped (its trial runs again)."""
    from services.apps.evaluation import TrialResult

    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines:
        return []
    try:
        first = json.loads(lines[0])["header"]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ConfigurationError(f"{path}: not an eval trial journal (no header line): {exc}") from exc
    differs = {k: (first.get(k), header.get(k)) for k in HEADER_KEYS if first.get(k) != header.get(k)}
    if differs:
        said = ", ".join(f"{k}: journal {a!r}, this run {b!r}" for k, (a, b) in differs.items())
        raise ConfigurationError(f"{path} is the journal of another evaluation ({said}); drop --resume")
    names = {f.name for f in dataclasses.fields(TrialResult)}
    results: list[TrialResult] = []
    for n, line in enumerate(lines[1:], start=2):
        try:
            record = json.loads(line)["trial"]
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            if n == len(lines):  # the write the interruption cut short
                break
            raise ConfigurationError(f"{path}:{n}: unreadable trial record: {exc}") from exc
        results.append(TrialResult(**{k: v for k, v in record.items() if k in names}))
    return results
