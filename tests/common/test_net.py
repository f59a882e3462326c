import re
import socket

from aeb_radar_camera.common.net import free_endpoint, free_port


def test_a_free_port_can_be_bound_on_loopback():
    port = free_port()
    assert 1024 <= port <= 65535
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


def test_a_free_endpoint_is_a_zenoh_tcp_loopback_endpoint():
    endpoint = free_endpoint()
    m = re.fullmatch(r"tcp/127\.0\.0\.1:(\d+)", endpoint)
    assert m is not None and 1024 <= int(m.group(1)) <= 65535
