"""gRPC helpers: an asyncio server factory and the one error-translation boundary.

Server side, :class:`ErrorTranslatingInterceptor` turns any :class:`RobotError`
raised by a servicer into a status code plus the error's class name in the
trailing metadata; any other exception becomes INTERNAL with its text (never a
bare stack trace). Client side, :func:`rpc_errors` maps them back.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import hmac
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, cast

import grpc
import grpc.aio

from services.common.errors import RobotCommunicationError, RobotError, error_class

if TYPE_CHECKING:
    from services.common.settings import Settings

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
        continuation: Callable[[grpc.HandlerCallDetails], Awaitable[grpc.RpcMethodHandler[Any, Any] | None]],
        handler_call_details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler[Any, Any] | None:
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
                # an async generator under grpc.aio (the stubs type the sync API's iterator)
                _wrap_stream(cast(Callable[..., AsyncIterator[Any]], handler.unary_stream)),
                request_deserializer=handler.request_deserializer,
                response_serializer=handler.response_serializer,
            )
        return handler


# --- authentication: every call of the cell's gRPC services carries the cell's token (gateway.api_token),
# ``authorization: Bearer <token>``, as at the gateway's edge; only the health check is open (probes).
AUTH_KEY = "authorization"


def cell_token(settings: Settings) -> str | None:
    """The cell's token (gateway.api_token): the gateway's edge and every gRPC service ask for it."""
    token = settings.gateway.api_token
    return token.get_secret_value() if token is not None else None


def bearer_metadata(token: str) -> tuple[tuple[str, str]]:
    return ((AUTH_KEY, f"Bearer {token}"),)


def _presented_token(metadata: Any) -> str | None:
    for key, value in metadata or ():
        if key == AUTH_KEY:
            scheme, _, token = str(value).partition(" ")
            return token.strip() if scheme.lower() == "bearer" and token.strip() else None
    return None


class TokenAuthInterceptor(grpc.aio.ServerInterceptor):
    """UNAUTHENTICATED for every call without the token (the health check excepted)."""

    def __init__(self, token: str):
        if not token:
            raise ValueError("an empty token authenticates nobody")
        self._token = token.encode()

    def allows(self, metadata: Any) -> bool:
        presented = _presented_token(metadata)
        return presented is not None and hmac.compare_digest(presented.encode(), self._token)

    async def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], Awaitable[grpc.RpcMethodHandler[Any, Any] | None]],
        details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler[Any, Any] | None:
        handler = await continuation(details)
        method = str(details.method or "")
        if (
            handler is None
            or method.startswith(f"/{HEALTH_SERVICE}/")
            or self.allows(details.invocation_metadata)
        ):
            return handler
        message = (
            "this service needs the cell's token: send 'authorization: Bearer <gateway.api_token>' metadata"
            if _presented_token(details.invocation_metadata) is None
            else "bearer token is not valid"
        )
        log.warning("refused an unauthenticated call to %s", method)
        return unauthenticated_handler(handler, message)


def unauthenticated_handler(
    handler: grpc.RpcMethodHandler[Any, Any], message: str
) -> grpc.RpcMethodHandler[Any, Any]:
    """A handler of the same kind as ``handler`` that refuses the call as UNAUTHENTICATED."""

    async def deny_unary(request: Any, context: grpc.aio.ServicerContext) -> Any:
        await context.abort(grpc.StatusCode.UNAUTHENTICATED, message)

    async def deny_stream(request: Any, context: grpc.aio.ServicerContext) -> AsyncIterator[Any]:
        await context.abort(grpc.StatusCode.UNAUTHENTICATED, message)
        yield  # pragma: no cover  (makes this an async generator)

    if handler.unary_stream is not None:
        return grpc.unary_stream_rpc_method_handler(
            deny_stream, handler.request_deserializer, handler.response_serializer
        )
    return grpc.unary_unary_rpc_method_handler(
        deny_unary, handler.request_deserializer, handler.response_serializer
    )


class _BearerUnaryUnary(grpc.aio.UnaryUnaryClientInterceptor):
    def __init__(self, token: str):
        self._md = bearer_metadata(token)

    async def intercept_unary_unary(self, continuation: Any, details: Any, request: Any) -> Any:
        return await continuation(_with_metadata(details, self._md), request)


class _BearerUnaryStream(grpc.aio.UnaryStreamClientInterceptor):
    def __init__(self, token: str):
        self._md = bearer_metadata(token)

    async def intercept_unary_stream(self, continuation: Any, details: Any, request: Any) -> Any:
        return await continuation(_with_metadata(details, self._md), request)


def _with_metadata(details: Any, extra: tuple[tuple[str, str], ...]) -> Any:
    metadata = [*(details.metadata or ()), *extra]
    return grpc.aio.ClientCallDetails(
        details.method,
        details.timeout,
        grpc.aio.Metadata(*metadata),
        details.credentials,
        details.wait_for_ready,
    )


def client_interceptors(token: str | None) -> list[grpc.aio.ClientInterceptor]:
    """What a channel needs to call the cell's services: the token on every call (none without one)."""
    return [] if not token else [_BearerUnaryUnary(token), _BearerUnaryStream(token)]


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


# --- health: the standard grpc.health.v1 check, so any gRPC probe (the launcher's, a Kubernetes grpc
# probe) asks the shell itself whether it serves, not merely whether its port accepts a connection.
HEALTH_SERVICE = "grpc.health.v1.Health"
HEALTH_DETAIL_KEY = "pickplace-health"  # trailing metadata: the shell's state and links, for people


class ServingStatus(enum.IntEnum):
    UNKNOWN = 0
    SERVING = 1
    NOT_SERVING = 2
    SERVICE_UNKNOWN = 3


def _health_messages() -> tuple[Any, Any]:
    """HealthCheckRequest / HealthCheckResponse of grpc/health/v1/health.proto, built from their schema."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    F = descriptor_pb2.FieldDescriptorProto
    fdp = descriptor_pb2.FileDescriptorProto(
        name="grpc/health/v1/health.proto", package="grpc.health.v1", syntax="proto3"
    )
    req = fdp.message_type.add(name="HealthCheckRequest")
    req.field.add(name="service", number=1, type=F.TYPE_STRING, label=F.LABEL_OPTIONAL)
    resp = fdp.message_type.add(name="HealthCheckResponse")
    status = resp.enum_type.add(name="ServingStatus")
    for st in ServingStatus:
        status.value.add(name=st.name, number=st.value)
    resp.field.add(
        name="status",
        number=1,
        type=F.TYPE_ENUM,
        label=F.LABEL_OPTIONAL,
        type_name=".grpc.health.v1.HealthCheckResponse.ServingStatus",
    )
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    return (
        message_factory.GetMessageClass(pool.FindMessageTypeByName("grpc.health.v1.HealthCheckRequest")),
        message_factory.GetMessageClass(pool.FindMessageTypeByName("grpc.health.v1.HealthCheckResponse")),
    )


HealthCheckRequest, HealthCheckResponse = _health_messages()


class HealthReport(Protocol):
    @property
    def serving(self) -> bool: ...

    def describe(self) -> str: ...


def add_health(server: grpc.aio.Server, report: Callable[[], HealthReport]) -> None:
    """Answer ``grpc.health.v1.Health/Check`` on ``server`` from ``report()`` (any service name)."""

    async def check(request: Any, context: grpc.aio.ServicerContext) -> Any:
        health = report()
        context.set_trailing_metadata(((HEALTH_DETAIL_KEY, health.describe()),))
        status = ServingStatus.SERVING if health.serving else ServingStatus.NOT_SERVING
        return HealthCheckResponse(status=int(status))

    handler = grpc.unary_unary_rpc_method_handler(
        check,
        request_deserializer=HealthCheckRequest.FromString,
        response_serializer=HealthCheckResponse.SerializeToString,
    )
    server.add_generic_rpc_handlers(
        (grpc.method_handlers_generic_handler(HEALTH_SERVICE, {"Check": handler}),)
    )


async def check_health(host: str, port: int, what: str, timeout_s: float = 3.0) -> str:
    """Ask a pickplace gRPC server whether it serves; what it said, or RobotCommunicationError."""
    async with channel(host, port) as ch:
        call = ch.unary_unary(
            f"/{HEALTH_SERVICE}/Check",
            request_serializer=HealthCheckRequest.SerializeToString,
            response_deserializer=HealthCheckResponse.FromString,
        )(HealthCheckRequest(), timeout=timeout_s, wait_for_ready=True)
        try:
            response = await call
            trailing = await call.trailing_metadata()
        except grpc.aio.AioRpcError as exc:
            raise RobotCommunicationError(
                f"{what} gRPC {host}:{port} not answering its health check: {exc.code().name}"
            ) from exc
    detail = (
        str(trailing[HEALTH_DETAIL_KEY]) if trailing is not None and HEALTH_DETAIL_KEY in trailing else ""
    )
    status = ServingStatus(response.status)
    if status is not ServingStatus.SERVING:
        raise RobotCommunicationError(f"{what} gRPC {host}:{port} {status.name}: {detail}")
    return f"{what} gRPC {host}:{port} serving ({detail})"


def translate(exc: grpc.RpcError) -> RobotError:
    """Map a gRPC error from a pickplace server back to the pickplace error it carried."""
    name = "RobotError"
    trailing: Any = exc.trailing_metadata() if hasattr(exc, "trailing_metadata") else None
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


def channel(
    host: str, port: int, token: str | None = None, options: list[tuple[str, Any]] | None = None
) -> grpc.aio.Channel:
    """A channel to a pickplace gRPC server; with ``token``, every call carries it."""
    target = f"{host}:{port}" if ":" not in host else f"[{host}]:{port}"
    return grpc.aio.insecure_channel(target, options=options, interceptors=client_interceptors(token))
