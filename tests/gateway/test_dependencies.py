"""Every route's dependencies are coroutines: FastAPI runs a plain function in its thread pool, a thread
hop (two wake-ups) on every request that uses it; on the e-stop's path those hops cost 2.7 ms median and
7.5 ms at worst with both cores busy (bench_estop)."""

from __future__ import annotations

import inspect
from collections.abc import Iterator

from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, APIWebSocketRoute
from starlette.routing import BaseRoute

from gateway.app import create_app
from services.common.settings import DatabaseSettings, Settings
from tests.gateway.conftest import gateway_settings


def _calls(dep: Dependant) -> Iterator[object]:
    for sub in dep.dependencies:
        if sub.call is not None:
            yield sub.call
        yield from _calls(sub)


def _routes(routes: list[BaseRoute]) -> Iterator[APIRoute | APIWebSocketRoute]:
    for r in routes:
        if isinstance(r, APIRoute | APIWebSocketRoute):
            yield r
        inner = getattr(r, "original_router", None)  # an included router (FastAPI wraps it)
        if inner is not None:
            yield from _routes(inner.routes)


def _runs_on_the_loop(call: object) -> bool:
    if inspect.iscoroutinefunction(call) or inspect.isasyncgenfunction(call):
        return True
    # a class instance (HTTPBearer): its __call__
    return not inspect.isfunction(call) and inspect.iscoroutinefunction(type(call).__call__)  # type: ignore[operator]


def test_no_route_dependency_runs_in_the_thread_pool(settings: Settings, tmp_path) -> None:  # type: ignore[no-untyped-def]
    db = DatabaseSettings(url=f"sqlite+aiosqlite:///{tmp_path / 'cell.db'}")
    app = create_app(gateway_settings(settings, db, tmp_path), serve_web=False)
    routes = list(_routes(app.routes))
    assert any(r.path.endswith("/system/estop") for r in routes)
    checked = 0
    for route in routes:
        for call in _calls(route.dependant):
            checked += 1
            name = getattr(call, "__qualname__", type(call).__qualname__)
            assert _runs_on_the_loop(call), f"{route.path}: dependency {name} would run in the thread pool"
    assert checked > len(routes) / 2  # the mutating routes' token check and the cell at least
