"""The one place REST errors are made: pickplace errors, validation, database outages → JSON bodies.

Every error body is ``{"error": <name>, "detail": <what was wrong, with the value>}``; validation
errors add ``"errors": [{"field": "body.robot.speed_ratio", "message": …}]``.
"""

from __future__ import annotations

import logging
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy import exc as sa_exc
from starlette.exceptions import HTTPException as StarletteHTTPException

from services.common import errors as E

log = logging.getLogger("pickplace.gateway.errors")

# Most specific first.
STATUS_BY_ERROR: list[tuple[type[E.RobotError], int]] = [
    (E.InvalidInputError, 422),
    (E.ObjectNotDetectedError, 404),
    (E.HardwareError, 503),  # RobotCommunicationError: a service or the robot is unreachable
    (E.SafetyError, 409),
    (E.PlanningError, 409),
    (E.ExecutionError, 409),
    (E.ConfigurationError, 409),
    (E.RobotError, 500),
]

HTTP_ERROR_NAMES = {
    400: "BadRequest",
    401: "Unauthorized",
    403: "Forbidden",
    404: "NotFound",
    405: "MethodNotAllowed",
    409: "Conflict",
    413: "RequestTooLarge",
    415: "UnsupportedMediaType",
    422: "ValidationError",
    503: "ServiceUnavailable",
}


HTTP_METHODS = {"get", "put", "post", "delete", "options", "head", "patch", "trace"}


def status_for(exc: E.RobotError) -> int:
    for cls, code in STATUS_BY_ERROR:
        if isinstance(exc, cls):
            return code
    return 500


def error_body(name: str, detail: str, **extra: Any) -> dict[str, Any]:
    return {"error": name, "detail": detail, **extra}


def field_path(loc: tuple[Any, ...] | list[Any]) -> str:
    return ".".join(str(p) for p in loc)


def validation_body(errors: list[dict[str, Any]]) -> dict[str, Any]:
    items = [{"field": field_path(e.get("loc", ())), "message": e.get("msg", "")} for e in errors]
    detail = "; ".join(f"{i['field']}: {i['message']}" for i in items) or "invalid request"
    return error_body("ValidationError", detail, errors=items)


def allowed_methods(app: FastAPI, path: str) -> list[str]:
    """The methods the OpenAPI document lists for this path (Starlette's own 405 names only those of
    the first route that matched); a literal path wins over a template (/calibration/handshake)."""
    table: list[tuple[re.Pattern[str], bool, list[str]]] | None = getattr(app.state, "allow_table", None)
    if table is None:
        table = []
        for template, ops in app.openapi().get("paths", {}).items():
            pattern = re.sub(r"\\\{[^}]+\\\}", "[^/]+", re.escape(template))
            methods = sorted(m.upper() for m in ops if m in HTTP_METHODS)
            table.append((re.compile(f"^{pattern}$"), "{" not in template, methods))
        app.state.allow_table = table
    matching = [(literal, methods) for rx, literal, methods in table if rx.match(path)]
    literal = [m for is_literal, m in matching if is_literal]
    chosen = literal or [m for _, m in matching]
    return sorted({m for methods in chosen for m in methods})


def install(app: FastAPI) -> None:
    @app.exception_handler(E.RobotError)
    async def _robot_error(_req: Request, exc: E.RobotError) -> JSONResponse:
        code = status_for(exc)
        if code >= 500 and code != 503:
            log.error("request failed: %s: %s", type(exc).__name__, exc)
        errors = getattr(exc, "errors", None)
        extra = {"errors": errors} if isinstance(errors, list) else {}
        return JSONResponse(error_body(type(exc).__name__, str(exc), **extra), status_code=code)

    @app.exception_handler(RequestValidationError)
    async def _validation(_req: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse(validation_body(list(exc.errors())), status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(req: Request, exc: StarletteHTTPException) -> JSONResponse:
        name = HTTP_ERROR_NAMES.get(exc.status_code, "HTTPError")
        headers = dict(getattr(exc, "headers", None) or {})
        if exc.status_code == 405:
            headers["Allow"] = ", ".join(allowed_methods(app, req.scope["path"]))
        return JSONResponse(
            error_body(name, str(exc.detail)), status_code=exc.status_code, headers=headers or None
        )

    @app.exception_handler(sa_exc.SQLAlchemyError)
    async def _database(_req: Request, exc: sa_exc.SQLAlchemyError) -> JSONResponse:
        text = str(exc).splitlines()[0][:300]
        if isinstance(exc, sa_exc.OperationalError | sa_exc.InterfaceError | sa_exc.TimeoutError) or (
            isinstance(exc, sa_exc.DBAPIError) and exc.connection_invalidated
        ):
            return JSONResponse(
                error_body("DatabaseUnavailable", f"database unavailable: {text}"), status_code=503
            )
        log.error("database error: %s", text)
        return JSONResponse(error_body("DatabaseError", text), status_code=500)

    @app.exception_handler(ConnectionError)
    async def _connection(_req: Request, exc: ConnectionError) -> JSONResponse:
        # asyncpg raises OSError (connection refused) before SQLAlchemy can wrap it
        return JSONResponse(
            error_body("DatabaseUnavailable", f"database unavailable: {type(exc).__name__}: {exc}"),
            status_code=503,
        )

    @app.exception_handler(Exception)
    async def _unexpected(_req: Request, exc: Exception) -> JSONResponse:
        # a bug: logged with its traceback here, never shown to the client
        log.exception("unhandled error in request")
        return JSONResponse(
            error_body("InternalError", "internal error (see the gateway's log)"), status_code=500
        )
