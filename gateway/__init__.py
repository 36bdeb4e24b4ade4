"""The gateway: LLD REST API, pick history database, Prometheus metrics, web dashboard, gRPC edge.

``create_app(settings)`` builds the FastAPI app (everything else is wired in its lifespan);
``GatewayServer`` runs it under uvicorn in the caller's event loop; ``embedded_gateway`` is the
variant for ``pickplace up``; ``serve`` is ``pickplace serve gateway``. See ``gateway/README.md``.
Imported lazily, so ``pickplace db …`` and the rest of the CLI do not load FastAPI.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "create_app": "gateway.app",
    "GatewayServer": "gateway.server",
    "embedded_gateway": "gateway.server",
    "serve": "gateway.server",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'gateway' has no attribute {name!r}")
