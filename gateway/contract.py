"""The API contract in the OpenAPI document: one error model on every status a route can answer,
the body of PUT /config generated from the settings it may change, and the links between operations.

What a route can answer:

- 401 when it carries the bearer token check (every mutating route);
- 404 for an id that names nothing; 409 when the cell's state refuses the command (the task already
  runs, an e-stop is active, no calibration routine is connected); 503 when the service it relays to
  (task service, robot driver, database) cannot be reached;
- 413 / 422 for a request body too large or invalid, 422 for an invalid path or query parameter.

Every one of those bodies is an :class:`ErrorBody` (``gateway.errors`` makes them all).
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, create_model, model_validator
from pydantic_core import PydanticCustomError

from services.common.config_patch import UPDATABLE
from services.common.settings import Settings

ERROR_DESCRIPTIONS: dict[int, str] = {
    400: "the request cannot be read (a body that is not UTF-8 JSON, a Content-Length that is no number)",
    401: "no bearer token, or not the gateway's (`Authorization: Bearer <gateway.api_token>`)",
    404: "nothing with that id",
    409: "the cell's current state refuses this (task already running, e-stop active, no routine)",
    413: "the request body exceeds gateway.max_request_bytes",
    422: "a parameter or the body is invalid; `errors` names each field",
    503: "a service this relays to (task service, robot driver, database) is unreachable",
}

LARGEST_ID = 2**63 - 1  # BIGINT on PostgreSQL, INTEGER (64-bit) on SQLite


class FieldError(BaseModel):
    field: str = Field(description="where: body.robot.speed_ratio, query.limit, path.pick_id")
    message: str


class ErrorBody(BaseModel):
    """Every error the gateway answers."""

    error: str = Field(description="the error's name: NotFound, ValidationError, RobotBusyError, …")
    detail: str = Field(description="what was wrong, with the value")
    errors: list[FieldError] | None = Field(None, description="one entry per invalid field (422)")


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` for a route: each status with the error model and what it means."""
    return {c: {"model": ErrorBody, "description": ERROR_DESCRIPTIONS[c]} for c in codes}


# What each kind of route may answer besides its success.
READ = errors(422)
READ_DB = errors(422, 503)
MUTATE = errors(400, 401, 413, 422, 503)
COMMAND = errors(400, 401, 409, 413, 422, 503)


def _json_int(value: Any) -> Any:
    """JSON's integer: 147 or 147.0, never true/false or "147" (JSON Schema's rule, stricter than lax)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"expected an integer, got {type(value).__name__} {value!r}")
    if isinstance(value, float):
        if not value.is_integer():
            raise ValueError(f"expected an integer, got {value!r}")
        return int(value)
    return value


# An integer field of a request body: JSON's idea of one (use as ``JsonInt`` in a model).
JsonInt = Annotated[int, BeforeValidator(_json_int), Field(strict=True)]


# ------------------------------------------------------------------ PUT /config's body
# Bounds a settings field checks in a validator (not a Field constraint) stated for the schema.
EXTRA_BOUNDS: dict[str, dict[str, Any]] = {"robot.speed_ratio": {"ge": 1, "le": 100}}
BOUND_NAMES = ("gt", "ge", "lt", "le", "multiple_of", "min_length", "max_length")


def _leaf_field(model: type[BaseModel], path: str, name: str) -> tuple[Any, Any]:
    info = model.model_fields[name]
    kwargs: dict[str, Any] = {"description": info.description}
    if info.annotation in (float, bool):
        kwargs["strict"] = True  # a bool is not a number, "30" is not 30 (an int is a float)
    kwargs.update(EXTRA_BOUNDS.get(path, {}))
    for meta in info.metadata:  # Ge(ge=1) → ge=1, and so on
        kwargs.update({k: getattr(meta, k) for k in BOUND_NAMES if hasattr(meta, k)})
    return (JsonInt if info.annotation is int else info.annotation), Field(None, **kwargs)


def config_patch_model(settings_type: type[BaseModel] = Settings) -> type[BaseModel]:
    """A pydantic model of every runtime-changeable setting (nested as the settings are); each
    object needs at least one member, nothing else is allowed."""
    tree: dict[str, Any] = {}
    for path in UPDATABLE:
        node = tree
        *parents, leaf = path.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = None

    def build(model: type[BaseModel], node: dict[str, Any], prefix: str, title: str) -> type[BaseModel]:
        fields: dict[str, Any] = {}
        for name, sub in node.items():
            path = f"{prefix}{name}"
            if sub is None:
                fields[name] = _leaf_field(model, path, name)
            else:
                child = model.model_fields[name].annotation
                assert isinstance(child, type) and issubclass(child, BaseModel), path
                sub_model = build(child, sub, path + ".", title + name.title().replace("_", ""))
                fields[name] = (sub_model, Field(None))
        cfg = ConfigDict(extra="forbid", json_schema_extra={"minProperties": 1})
        known = tuple(node)

        def only_updatable(cls: type[BaseModel], value: Any) -> Any:
            if isinstance(value, dict):
                unknown = [k for k in value if k not in known]
                if unknown:
                    raise PydanticCustomError(
                        "not_updatable",
                        "{names} cannot be changed at runtime (changeable here: {known})",
                        {"names": ", ".join(f"{prefix}{k}" for k in unknown), "known": ", ".join(known)},
                    )
                if not value:
                    raise PydanticCustomError("empty", "name at least one setting to change", {})
            return value

        validators: dict[str, Any] = {"only_updatable": model_validator(mode="before")(only_updatable)}
        return create_model(title, __config__=cfg, __validators__=validators, **fields)

    return build(settings_type, tree, "", "ConfigPatch")


def patch_document(patch: BaseModel) -> dict[str, Any]:
    """The members the client sent, as the partial settings document ``apply_patch`` takes."""
    return patch.model_dump(exclude_unset=True, mode="json")


# ------------------------------------------------------------------ links for stateful testing
def calibration_links() -> dict[str, Any]:
    return {
        "GetCalibration": {
            "operationId": "get_calibration",
            "parameters": {"calibration_id": "$response.body#/calibration_id"},
            "description": "the run just started",
        }
    }


def pick_links() -> dict[str, Any]:
    return {
        "GetPick": {
            "operationId": "get_pick",
            "parameters": {"pick_id": "$response.body#/0/id"},
            "description": "the newest pick of the page",
        }
    }
