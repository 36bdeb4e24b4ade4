"""gRPC helpers: an asyncio server factory and the one error-translation boundary.

Server side, :class:`ErrorTranslatingInterceptor` turns any :class:`RobotError`
raised by a servicer into a status code plus the error's class name in the
trailing metadata; any other exception becomes INTERNAL with its text (never a
bare stack trace). Client side, :func:`rpc_errors` maps them back.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from typing import Any, TypeVar

import grpc
import grpc.aio

from services.common.errors import RobotCommunicationError, RobotError, error_class

log = logging.getLogger("pickplace.grpc")

ERROR_TYPE_KEY = "pickplace-error-type"

T = TypeVar("T")


def _status_for(exc: BaseException) -> tuple[grpc.StatusCode, str, str]:
    if isinstance(exc, RobotError):
        return exc.grpc_code, f"{type(exc).__name__}: {exc}", type(exc).__name__
    return grpc.StatusCode.INTERNAL, f"{type(exc).__name__}: {exc}", "RobotError"


async def _abort(context: grpc.aio.ServicerContext, exc: BaseException) -> None:
    code, message, name = _status_for(exc)
    if code == grpc.StatusCode.INTERNAL:
        log.error("unhandled error in gRPC handler: %s", message, exc_info=exc)
    context.set_trailing_metadata(((ERROR_TYPE_KEY, name),))
    await context.abort(code, message)


def _wrap_unary(fn: Callable[..., Awaitable[Any]]) -> Callable[..., Awaitable[Any]]:
    async def handler(request: Any, context: grpc.aio.ServicerContext) -> Any:
        try:
            return await fn(request, context)
        except (grpc.aio.AbortError, grpc.RpcError):
            raise
        except Exception as exc:
            await _abort(context, exc)

    return handler


def _wrap_stream(fn: Callable[..., AsyncIterator[Any]]) -> Callable[..., AsyncIterator[Any]]:
    async def handler(request: Any, context: grpc.aio.ServicerContext) -> AsyncIterator[Any]:
        try:
            async for item in fn(request, context):
                yield item
        except (grpc.aio.AbortError, grpc.RpcError):
            raise
        except Exception as exc:
            await _abort(context, exc)

    return handler


class ErrorTranslatingInterceptor(grpc.aio.ServerInterceptor):
    async def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], Awaitable[grpc.RpcMethodHandler]],
        handler_call_details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler:
        handler = await continuation(handler_call_details)
        if handler is None:
            return handler
        if handler.unary_unary is not None:
            return grpc.unary_unary_rpc_method_handler(
                _wrap_unary(handler.unary_unary),
                request_deserializer=handler.request_deserializer,
                response_serializer=handler.response_serializer,
            )
        if handler.unary_stream is not None:
            return grpc.unary_stream_rpc_method_handler(
                _wrap_stream(handler.unary_stream),
                request_deserializer=handler.request_deserializer,
                response_serializer=handler.response_serializer,
            )
        return handler


def create_server(extra_interceptors: list[grpc.aio.ServerInterceptor] | None = None) -> grpc.aio.Server:
    return grpc.aio.server(
        interceptors=[*(extra_interceptors or []), ErrorTranslatingInterceptor()],
        options=[("grpc.so_reuseport", 0)],
    )


def bind(server: grpc.aio.Server, host: str, port: int) -> int:
    """Bind an insecure loopback-or-configured port; return the port actually bound (0 = any free)."""
    bound = server.add_insecure_port(f"{host}:{port}" if ":" not in host else f"[{host}]:{port}")
    if bound == 0:
        raise RobotCommunicationError(f"cannot bind gRPC server on {host}:{port}")
    return bound


async def serve_until_terminated(server: grpc.aio.Server, what: str, host: str, port: int) -> None:
    """Start a built server, say where it serves, and run it until cancelled or terminated."""
    await server.start()
    log.info("%s serving on %s:%d", what, host, port)
    try:
        await server.wait_for_termination()
    finally:
        await server.stop(grace=0.5)


def translate(exc: grpc.RpcError) -> RobotError:
    """Map a gRPC error from a pickplace server back to the pickplace error it carried."""
    name = "RobotError"
    trailing = exc.trailing_metadata() if hasattr(exc, "trailing_metadata") else None
    for key, value in trailing or ():
        if key == ERROR_TYPE_KEY:
            name = str(value)
    code = exc.code() if hasattr(exc, "code") else None
    details = exc.details() if hasattr(exc, "details") else str(exc)
    if name == "RobotError" and code in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED):
        return RobotCommunicationError(f"gRPC {code.name}: {details}")
    cls = error_class(name)
    prefix = f"{name}: "
    message = details[len(prefix) :] if details and details.startswith(prefix) else details
    return cls(message or f"gRPC {code}")


@contextlib.contextmanager
def rpc_errors() -> Iterator[None]:
    """``with rpc_errors(): await stub.X(req)`` raises pickplace errors instead of grpc.RpcError."""
    try:
        yield
    except grpc.RpcError as exc:
        raise translate(exc) from exc


async def run_metered(rpc: str, fn: Callable[[], T], requests: Any, seconds: Any) -> T:
    """Run a CPU-bound request off the event loop, counting its outcome and timing it.

    ``requests`` is a Counter labelled (rpc, outcome), ``seconds`` a Histogram labelled (rpc)."""
    t0 = time.perf_counter()
    try:
        result = await asyncio.to_thread(fn)
    except RobotError as exc:
        requests.labels(rpc, type(exc).__name__).inc()
        log.info("%s refused: %s: %s", rpc, type(exc).__name__, exc)
        raise
    except Exception:
        requests.labels(rpc, "internal").inc()
        raise
    requests.labels(rpc, "ok").inc()
    seconds.labels(rpc).observe(time.perf_counter() - t0)
    return result


def channel(host: str, port: int) -> grpc.aio.Channel:
    target = f"{host}:{port}" if ":" not in host else f"[{host}]:{port}"
    return grpc.aio.insecure_channel(target)
