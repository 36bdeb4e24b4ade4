"""Loopback port helpers (tests, benchmarks, self-contained runs).

Ports are chosen *below* the kernel's ephemeral range (``ip_local_port_range``): a port from
``bind(0)`` is one the kernel may hand to the next outgoing connection or ``bind(0)`` of any
process before our server binds it (seen in CI: a gateway's Zenoh listener found its port taken).
Outside that range only an explicit bind can take it, and this process never hands one out twice.
"""

from __future__ import annotations

import os
import random
import socket
import threading
import time
from pathlib import Path

_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
_LOWEST = 10_000  # above the well-known and most registered service ports
_FALLBACK_EPHEMERAL_LOW = 32_768  # Linux default when /proc cannot be read
_given: set[int] = set()
_lock = threading.Lock()
_rng = random.Random(os.getpid() ^ time.time_ns())


def ephemeral_low() -> int:
    """The lowest port the kernel assigns on its own (Linux ``ip_local_port_range``)."""
    try:
        low = int(_RANGE_FILE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return _FALLBACK_EPHEMERAL_LOW
    return low if low > _LOWEST + 1000 else _FALLBACK_EPHEMERAL_LOW


def _bindable(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_loopback_ports(n: int, tries: int = 10_000) -> list[int]:
    """``n`` distinct TCP ports on 127.0.0.1, free now, outside the ephemeral range, and never
    handed out before by this process. A random start keeps parallel processes apart."""
    high = ephemeral_low()
    out: list[int] = []
    with _lock:
        for _ in range(tries):
            if len(out) == n:
                break
            port = _rng.randrange(_LOWEST, high)
            if port in _given or not _bindable(port):
                continue
            _given.add(port)
            out.append(port)
    if len(out) < n:
        raise RuntimeError(f"found only {len(out)} of {n} free loopback ports in {_LOWEST}..{high - 1}")
    return out


def free_loopback_port() -> int:
    return free_loopback_ports(1)[0]
