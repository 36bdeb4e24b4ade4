"""The dashboard's static files, and three.js / urdf-loader from web/node_modules (no CDN)."""

from __future__ import annotations

import logging
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

from services.common.settings import Settings

log = logging.getLogger("pickplace.gateway.web")

VENDOR = {
    # URL prefix -> folder inside web/node_modules
    "/vendor/three": "three",
    "/vendor/urdf-loader": "urdf-loader/src",
}


def mount(app: FastAPI, web_dir: Path, settings: Settings) -> None:
    index = web_dir / "index.html"
    if not index.exists():
        log.warning("no dashboard at %s; the API still works", web_dir)
        return
    app.mount("/static", StaticFiles(directory=web_dir / "static"), name="static")
    for prefix, sub in VENDOR.items():
        folder = web_dir / "node_modules" / sub
        if folder.is_dir():
            app.mount(prefix, StaticFiles(directory=folder), name=prefix.strip("/").replace("/", "-"))
        else:
            log.warning("%s missing: the dashboard's 3D view needs `make install` (npm ci in web/)", folder)

    @app.get("/", include_in_schema=False)
    async def dashboard() -> FileResponse:
        return FileResponse(index, headers={"Cache-Control": "no-cache"})

    @app.get("/index.html", include_in_schema=False)
    async def dashboard_alias() -> RedirectResponse:
        return RedirectResponse("/")
