"""Loopback ports for tests and self-contained runs stay out of the kernel's ephemeral range."""

from __future__ import annotations

import socket

from services.common.net import ephemeral_low, free_loopback_ports


def test_ports_are_distinct_bindable_and_outside_the_ephemeral_range() -> None:
    low = ephemeral_low()
    first = free_loopback_ports(20)
    second = free_loopback_ports(20)
    ports = first + second
    assert len(set(ports)) == 40  # never handed out twice by one process
    assert all(10_000 <= p < low for p in ports)
    for p in ports:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", p))


def test_an_outgoing_connection_never_takes_a_chosen_port() -> None:
    # The kernel picks a client's local port from the ephemeral range, so it cannot be ours.
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        clients = []
        try:
            for _ in range(50):
                c = socket.create_connection(server.getsockname())
                clients.append(c)
            local = {c.getsockname()[1] for c in clients}
            chosen = set(free_loopback_ports(30))
            assert local.isdisjoint(chosen)
            assert all(p < ephemeral_low() for p in chosen)
        finally:
            for c in clients:
                c.close()
