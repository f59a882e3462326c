"""Free loopback ports, for the single-host tools, benchmarks and tests (explicit
endpoints, no scouting: each run picks its own)."""

import socket
import time


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on at this moment (the OS picks it). Another process can
    take it before the caller binds it: callers that can, retry."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def free_endpoint(host: str = "127.0.0.1") -> str:
    """A Zenoh TCP endpoint on a free loopback port: ``tcp/127.0.0.1:<port>``."""
    return f"tcp/{host}:{free_port(host)}"


def port_open(port: int, host: str = "127.0.0.1") -> bool:
    """Whether something accepts TCP connections on `host`:`port` now."""
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False


def wait_listening(port: int, timeout_s: float, host: str = "127.0.0.1") -> None:
    """Until something accepts TCP connections on `host`:`port` (a router just started).
    Raises TimeoutError after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not port_open(port, host):
        if time.monotonic() > deadline:
            raise TimeoutError(f"nothing listens on {host}:{port} after {timeout_s:g} s")
        time.sleep(0.05)
