"""What every settings section shares: the strict base model, loopback checks, vector aliases."""

from __future__ import annotations

import ipaddress
from typing import Literal

from pydantic import BaseModel

LOOPBACK_HOSTS = {"localhost", "ip6-localhost"}


def is_loopback(host: str) -> bool:
    if host in LOOPBACK_HOSTS:
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def endpoint_host(endpoint: str) -> str:
    """Host part of a Zenoh endpoint such as ``tcp/127.0.0.1:7447`` or ``tcp/[::1]:7447``."""
    locator = endpoint.split("/", 1)[-1].split("#", 1)[0]
    host, _, _port = locator.rpartition(":")
    return host.strip("[]")


class Model(BaseModel):
    model_config = {"extra": "forbid", "validate_assignment": True}


Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
CubeColor = Literal["red", "blue", "green", "black", "yellow"]
ALL_CUBE_COLORS: tuple[CubeColor, ...] = ("red", "blue", "green", "black")
# seed 004's colour-keyed drop zones (base frame, m): where grasp puts the cubes and the twin marks them
DEFAULT_DROP_ZONES_M: dict[str, tuple[float, float]] = {
    "red": (0.30, 0.45),
    "blue": (0.45, 0.45),
    "green": (0.30, -0.45),
    "black": (0.45, -0.45),
    "yellow": (0.60, 0.45),  # the colour table's fifth colour: the +y row continued
}

Vec6 = tuple[float, float, float, float, float, float]
