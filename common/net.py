"""Free loopback ports, for the single-host tools, benchmarks and tests (explicit
endpoints, no scouting: each run picks its own)."""

import socket


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on at this moment (the OS picks it). Another process can
    take it before the caller binds it: callers that can, retry."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def free_endpoint(host: str = "127.0.0.1") -> str:
    """A Zenoh TCP endpoint on a free loopback port: ``tcp/127.0.0.1:<port>``."""
    return f"tcp/{host}:{free_port(host)}"
