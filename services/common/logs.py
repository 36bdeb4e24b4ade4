"""Logging: console (rich when interactive) plus a rotating file."""

from __future__ import annotations

import logging
import logging.handlers
from pathlib import Path

from services.common.settings import REPO_ROOT, LoggingSettings

FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"
# The name of the handlers setup_logging installs, so that a second call replaces them.
HANDLER_NAME = "pickplace"


def setup_logging(settings: LoggingSettings, console: bool = True) -> None:
    root = logging.getLogger()
    root.setLevel(settings.level)
    for h in list(root.handlers):
        if h.name == HANDLER_NAME:
            root.removeHandler(h)
    handlers: list[logging.Handler] = []
    if console:
        ch = logging.StreamHandler()
        ch.setFormatter(logging.Formatter(FORMAT))
        handlers.append(ch)
    if settings.file:
        path = Path(settings.file)
        if not path.is_absolute():
            path = REPO_ROOT / path
        path.parent.mkdir(parents=True, exist_ok=True)
        fh = logging.handlers.RotatingFileHandler(
            path, maxBytes=settings.max_bytes, backupCount=settings.backups
        )
        fh.setFormatter(logging.Formatter(FORMAT))
        handlers.append(fh)
    for h in handlers:
        h.set_name(HANDLER_NAME)
        root.addHandler(h)
    # toppra reports every infeasible grid point it retries around; our timing handles those
    logging.getLogger("toppra").setLevel(logging.ERROR)
