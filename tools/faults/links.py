"""The links the harness can cut: fusion's link to the router, either between two
network namespaces (fusion alone in its own namespace joined to the root namespace by a
veth pair: the link taken down), or, where namespaces cannot be made, a TCP relay on
loopback that the harness stops forwarding (the port blocked); and the CAN link of the
SIMULATED radar (a gate on its frames: silence, or a cycle cut in the middle)."""

import contextlib
import os
import selectors
import socket
import subprocess
import threading
from collections.abc import Sequence
from typing import Any

from aeb_radar_camera.tools.launch.table import Launch


def _ip(*args: str, netns: str = "") -> subprocess.CompletedProcess[str]:
    cmd = ["ip", *(["netns", "exec", netns, "ip"] if netns else []), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=30, check=False)


class NetnsLink:
    """A namespace `aeb-f-<pid>` joined to the root namespace by a veth pair. `make()`
    returns "" or why it cannot be made (not root, no `ip`, no netns support)."""

    def __init__(self) -> None:
        tag = f"{os.getpid() % 100000}"
        self.ns, self.side_a, self.side_b = f"aeb-f-{tag}", f"aeb{tag}fa", f"aeb{tag}fb"
        net = f"10.78.{os.getpid() % 250}"
        self.address, self.peer = f"{net}.1", f"{net}.2"
        self.kind = "netns"
        self._made = False

    def make(self) -> str:
        if os.geteuid() != 0:
            return "network namespaces need root"
        steps = [
            (["netns", "add", self.ns], ""),
            (["link", "add", self.side_a, "type", "veth", "peer", "name", self.side_b], ""),
            (["link", "set", self.side_b, "netns", self.ns], ""),
            (["addr", "add", f"{self.address}/30", "dev", self.side_a], ""),
            (["link", "set", self.side_a, "up"], ""),
            (["addr", "add", f"{self.peer}/30", "dev", self.side_b], self.ns),
            (["link", "set", self.side_b, "up"], self.ns),
            (["link", "set", "lo", "up"], self.ns),
        ]
        self._made = True
        for args, where in steps:
            try:
                proc = _ip(*args, netns=where)
            except (OSError, subprocess.SubprocessError) as exc:
                self.remove()
                return f"cannot run ip: {exc}"
            if proc.returncode != 0:
                self.remove()
                return f"ip {' '.join(args)}: {proc.stderr.strip()}"
        return ""

    def endpoint(self, port: int) -> str:
        return f"tcp/{self.address}:{port}"

    def adapt(self, launch: Launch, local: str, port: int) -> Launch:
        """Fusion runs in the namespace and connects over the veth pair."""
        if launch.name != "fusion":
            return launch
        argv = [self.endpoint(port) if a == local else a for a in launch.argv]
        return _replace(launch, ("ip", "netns", "exec", self.ns, *argv))

    def cut(self) -> None:
        _ip("link", "set", self.side_a, "down")

    def restore(self) -> None:
        _ip("link", "set", self.side_a, "up")

    def remove(self) -> None:
        if self._made:
            _ip("link", "del", self.side_a)
            _ip("netns", "del", self.ns)
            self._made = False


def _replace(launch: Launch, argv: tuple[str, ...]) -> Launch:
    from dataclasses import replace
    return replace(launch, argv=argv)


class RelayLink:
    """Loopback fallback: fusion connects to a TCP relay in front of the router; cut()
    closes every relayed connection and refuses new ones until restore()."""

    def __init__(self, target_port: int) -> None:
        self.kind = "loopback relay"
        self._target = ("127.0.0.1", target_port)
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._open = threading.Event()
        self._open.set()
        self._lock = threading.Lock()
        self._pairs: list[tuple[socket.socket, socket.socket]] = []
        self._stop = False
        threading.Thread(target=self._accept, name="relay", daemon=True).start()

    def adapt(self, launch: Launch, local: str, port: int) -> Launch:
        if launch.name != "fusion":
            return launch
        argv = tuple(f"tcp/127.0.0.1:{self.port}" if a == local else a for a in launch.argv)
        return _replace(launch, argv)

    def _accept(self) -> None:
        while not self._stop:
            try:
                client, _ = self._listener.accept()
            except OSError:
                return
            if not self._open.is_set():
                client.close()
                continue
            try:
                upstream = socket.create_connection(self._target, timeout=2.0)
            except OSError:
                client.close()
                continue
            with self._lock:
                self._pairs.append((client, upstream))
            threading.Thread(target=self._pump, args=(client, upstream), daemon=True).start()

    def _pump(self, a: socket.socket, b: socket.socket) -> None:
        sel = selectors.DefaultSelector()
        sel.register(a, selectors.EVENT_READ, b)
        sel.register(b, selectors.EVENT_READ, a)
        try:
            while self._open.is_set():
                for key, _ in sel.select(0.2):
                    src: Any = key.fileobj
                    data = src.recv(65536)
                    if not data:
                        return
                    key.data.sendall(data)
        except OSError:
            return
        finally:
            sel.close()
            for s in (a, b):
                with contextlib.suppress(OSError):
                    s.close()

    def cut(self) -> None:
        self._open.clear()
        with self._lock:
            pairs, self._pairs = self._pairs, []
        for a, b in pairs:
            for s in (a, b):
                with contextlib.suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)

    def restore(self) -> None:
        self._open.set()

    def remove(self) -> None:
        self._stop = True
        self.cut()
        with contextlib.suppress(OSError):
            self._listener.close()


class CanGate:
    """Between the SIMULATED radar and its CAN link: passes frames, drops them all
    (silence), or passes `n` more frames and then drops everything (a radar that stops
    in the middle of a cycle)."""

    def __init__(self, sink: Any) -> None:
        self.sink = sink
        self._lock = threading.Lock()
        self._left: int | None = None     # None: pass everything
        self.dropped = 0

    def send(self, frames: Sequence[Any]) -> None:
        with self._lock:
            if self._left is None:
                out = list(frames)
            else:
                out = list(frames[:self._left])
                self._left -= len(out)
                self.dropped += len(frames) - len(out)
        if out:
            self.sink.send(out)

    def silence(self, after_frames: int = 0) -> None:
        with self._lock:
            self._left = after_frames

    def restore(self) -> None:
        with self._lock:
            self._left = None
