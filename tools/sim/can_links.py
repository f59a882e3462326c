"""The radar's side of a CAN link that crosses processes: for tests and the scenario
simulator. SIMULATION of the wire only: the service under test uses python-can's real
`slcan` / `socketcand` interfaces, exactly as with a USB-CAN adapter or a socketcand
daemon in front of a real radar.

`SlcanPtyLink`: a pseudo-terminal pair that behaves like an slcan USB-CAN adapter with a
radar behind it. The service opens `link.path` with python-can's ``slcan`` interface
(use option ``sleep_after_open = 0``: python-can otherwise sleeps 2 s after opening)::

    from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, object_cycle_frames
    from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink, replay_log

    with SlcanPtyLink() as link:
        # [radar.can] interface = "slcan", channel = link.path,
        #             options = { sleep_after_open = 0 }
        link.wait_open(timeout_s=30)                    # the adapter saw "O" (open)
        link.send(object_cycle_frames([ObjectGeneral(1, 12.0, 0.4, -3.0, 0.0, 0, 10.0)], 0))
        cfg = link.wait_frame(lambda f: f.arb_id == 0x200, timeout_s=5)  # service -> radar
        link.received()                                 # the frames the service wrote
        link.commands                                   # slcan commands: ["C", "S6", "O"]

`SocketcandServer`: a minimal socketcand server on 127.0.0.1 (one client at a time) for
python-can's ``socketcand`` interface: channel = any name, options host / port =
`server.host` / `server.port`. Same API as the pty link.

`replay_log(path, link, pace="realtime"|"fast", loop=False, stop=None)` feeds a recorded
log (any format python-can reads) into a link.

Both links: `send(frames)` writes radar -> service frames (thread-safe; blocks while the
reader lags, as a real bus would back-pressure nothing but a pty does); `on_frame`
(constructor argument, or `add_listener` later) is called from the link's reader thread
for every frame the service writes (e.g. answer a 0x200 with a 0x201; the simulated
radar reads the ego motion the service forwards); `wait_frame(predicate, timeout_s)`
returns the first received frame matching, or raises TimeoutError; `close()` (or leaving
the `with` block) ends the link: the service sees its bus vanish.
"""

import contextlib
import logging
import os
import select
import socket
import threading
import time
import tty
from collections.abc import Callable, Iterable
from typing import Self

import can

from aeb_radar_camera.services.radar.ars408.codec import RadarFrame
from aeb_radar_camera.services.radar.ports import radar_frame
from aeb_radar_camera.tools.arrivals import Arrivals

FrameCallback = Callable[[RadarFrame], None]

_log = logging.getLogger("sim.can_links")

# The frames from the service kept for `received` and `wait_frame` (about 3 min of the
# ego motion it forwards at 50 Hz): a run's whole history grew without bound, and every
# frame kept is an object each full garbage collection walks, a pause that stalls the
# simulator's other threads.
FRAMES_KEPT = 20_000

# python-can's socketcand client matches each handshake reply with one recv(): a frame
# sent right after the last "< ok >" could arrive glued to it. Wait this long first.
SOCKETCAND_SETTLE_S = 0.1


class _Link:
    """Received-frame bookkeeping shared by the links."""

    def __init__(self, on_frame: FrameCallback | None) -> None:
        self._listeners: list[FrameCallback] = [on_frame] if on_frame is not None else []
        self._frames: Arrivals[RadarFrame] = Arrivals(keep=FRAMES_KEPT)
        self._stop = threading.Event()
        self._opened = threading.Event()
        self.commands: list[str] = []
        self.callback_errors = 0

    def add_listener(self, callback: FrameCallback) -> None:
        """Call `callback` (on the link's reader thread) for every frame the service
        writes from now on, as the constructor's `on_frame`."""
        self._listeners = [*self._listeners, callback]

    def _got(self, frame: RadarFrame) -> None:
        self._frames.add(frame)
        for listener in self._listeners:
            try:
                listener(frame)
            except Exception:
                # The caller's callback must not stop the link's reader: count and log it.
                self.callback_errors += 1
                _log.exception("can link: on_frame failed for 0x%03X", frame.arb_id)

    def received(self) -> list[RadarFrame]:
        """The frames the service wrote so far (the newest FRAMES_KEPT at most)."""
        return self._frames.items

    def wait_frame(self, predicate: Callable[[RadarFrame], bool], timeout_s: float) -> RadarFrame:
        """The first received frame matching `predicate`. Raises TimeoutError."""
        return self._frames.wait(predicate, timeout_s, what="matching frame")[1]

    def wait_open(self, timeout_s: float) -> None:
        """Until the service opened the channel. Raises TimeoutError."""
        if not self._opened.wait(timeout_s):
            raise TimeoutError(f"the service did not open the link within {timeout_s} s")

    @property
    def opened(self) -> bool:
        return self._opened.is_set()

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def slcan_line(frame: RadarFrame) -> bytes:
    """`tIIIL<data>\\r`: one standard frame as an slcan adapter forwards it."""
    return f"t{frame.arb_id:03X}{len(frame.data)}{frame.data.hex().upper()}\r".encode()


def parse_slcan_frame(line: str) -> RadarFrame | None:
    """A `tIIIL<data>` line (without the CR) as a RadarFrame; None if it is not one."""
    if len(line) < 5 or line[0] != "t":
        return None
    try:
        dlc = int(line[4])
        return RadarFrame(int(line[1:4], 16), bytes.fromhex(line[5:5 + 2 * dlc]))
    except ValueError:
        return None


class SlcanPtyLink(_Link):
    """An slcan adapter on a pty pair. `path` is the device the service opens."""

    def __init__(self, on_frame: FrameCallback | None = None) -> None:
        super().__init__(on_frame)
        self._master, self._slave = os.openpty()
        # Raw at once: line discipline would echo and translate CR before anyone reads.
        tty.setraw(self._slave)
        self.path = os.ttyname(self._slave)
        self._write_lock = threading.Lock()
        self._thread = threading.Thread(target=self._read_loop, name="slcan-link", daemon=True)
        self._thread.start()

    def send(self, frames: Iterable[RadarFrame]) -> None:
        """Write radar -> service frames. Raises OSError once the link is closed."""
        self.send_raw(b"".join(slcan_line(f) for f in frames))

    def send_raw(self, data: bytes) -> None:
        """Write bytes as the adapter would (line noise, a line cut in two, ...). Raises
        OSError once the link is closed."""
        with self._write_lock:
            view = memoryview(data)
            while view:
                n = os.write(self._master, view)
                view = view[n:]

    def _read_loop(self) -> None:
        buf = b""
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.1)
                if not ready:
                    continue
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            *lines, buf = buf.split(b"\r")
            for raw in lines:
                self._line(raw.decode("ascii", errors="replace"))

    def _line(self, line: str) -> None:
        frame = parse_slcan_frame(line)
        if frame is not None:
            self._got(frame)
            return
        self.commands.append(line)
        if line in ("O", "L"):
            self._opened.set()
        elif line == "C":
            self._opened.clear()

    def close(self) -> None:
        """End the link (idempotent): the service's reads fail, as when a USB adapter is
        unplugged."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=2)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)


def socketcand_frame(frame: RadarFrame, timestamp_s: float) -> bytes:
    """`< frame ID SECS.USECS DATA >` as socketcand sends a received frame."""
    return f"< frame {frame.arb_id:03X} {timestamp_s:.6f} {frame.data.hex().upper()} >".encode()


def parse_socketcand_send(message: str) -> RadarFrame | None:
    """`< send ID DLC B0 B1 ... >` (what python-can writes) as a RadarFrame; None otherwise."""
    parts = message.strip("<> ").split()
    if len(parts) < 3 or parts[0] != "send":
        return None
    try:
        dlc = int(parts[2], 16)
        return RadarFrame(int(parts[1], 16), bytes(int(b, 16) for b in parts[3:3 + dlc]))
    except ValueError:
        return None


class SocketcandServer(_Link):
    """A socketcand server on 127.0.0.1 serving one channel in raw mode, one client at a
    time (a new client replaces the old one)."""

    def __init__(self, on_frame: FrameCallback | None = None, port: int = 0,
                 host: str = "127.0.0.1") -> None:
        super().__init__(on_frame)
        self._server = socket.create_server((host, port))
        self.host, self.port = self._server.getsockname()[:2]
        self._client: socket.socket | None = None
        self._write_lock = threading.Lock()
        self._thread = threading.Thread(target=self._serve, name="socketcand-link",
                                        daemon=True)
        self._thread.start()

    def send(self, frames: Iterable[RadarFrame]) -> None:
        """Write radar -> service frames. Raises ConnectionError when no client is in
        raw mode."""
        now = time.time()
        data = b"".join(socketcand_frame(f, now) for f in frames)
        with self._write_lock:
            if self._client is None or not self._opened.is_set():
                raise ConnectionError("no socketcand client in raw mode")
            self._client.sendall(data)

    def _serve(self) -> None:
        self._server.settimeout(0.1)
        while not self._stop.is_set():
            try:
                client, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._write_lock:
                self._opened.clear()
                self._client = client
            self._session(client)

    def _session(self, client: socket.socket) -> None:
        client.sendall(b"< hi >")
        buf = ""
        client.settimeout(0.1)
        while not self._stop.is_set():
            try:
                chunk = client.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                break
            if not chunk:
                break
            buf += chunk.decode("ascii", errors="replace")
            while ">" in buf:
                message, buf = buf.split(">", 1)
                self._message(client, message.strip() + " >")
        with self._write_lock:
            self._opened.clear()
            self._client = None
        client.close()

    def _message(self, client: socket.socket, message: str) -> None:
        if message.startswith("< send "):
            frame = parse_socketcand_send(message)
            if frame is not None:
                self._got(frame)
            return
        self.commands.append(message)
        if message.startswith("< open "):
            client.sendall(b"< ok >")
        elif message.startswith("< rawmode"):
            client.sendall(b"< ok >")
            time.sleep(SOCKETCAND_SETTLE_S)
            self._opened.set()

    def close(self) -> None:
        """Stop serving (idempotent): the client sees the connection drop."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._server.close()
        with self._write_lock:
            if self._client is not None:
                self._client.close()
        self._thread.join(timeout=2)


def replay_log(
    path: str,
    send: Callable[[Iterable[RadarFrame]], None],
    pace: str = "realtime",
    loop: bool = False,
    stop: threading.Event | None = None,
    max_duration_s: float | None = None,
) -> int:
    """Feed a recorded log into `send` (e.g. `link.send`); returns the frames sent.

    `pace`: ``realtime`` keeps the recorded spacing, ``fast`` sends as fast as the
    receiver takes them. Stops at the end (or loops), when `stop` is set, or after
    `max_duration_s` of recorded time.
    """
    sent = 0
    start = time.monotonic()
    offset = 0.0
    while True:
        first: float | None = None
        last = 0.0
        with can.LogReader(path) as reader:
            for msg in reader:
                if stop is not None and stop.is_set():
                    return sent
                if first is None:
                    first = msg.timestamp
                t = msg.timestamp - first + offset
                if max_duration_s is not None and t > max_duration_s:
                    return sent
                if pace == "realtime":
                    wait = start + t - time.monotonic()
                    if wait > 0:
                        if stop is not None:
                            if stop.wait(wait):
                                return sent
                        else:
                            time.sleep(wait)
                send([radar_frame(msg)])
                sent += 1
                last = t
        if not loop or first is None:
            return sent
        offset = last + 0.075
