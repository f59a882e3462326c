"""`aeb foxglove` as a Foxglove client sees it: a WebSocket client (the `websockets`
package) connects to the bridge, subscribes to the camera and the annotation channels,
and decodes what arrives with the schemas the server advertised.

foxglove-sdk 0.30 serves the protocol as subprotocol `foxglove.sdk.v1` (the successor of
ws-protocol's `foxglove.websocket.v1`, which it refuses); the client offers both, as
Foxglove does, and speaks the messages of the ws-protocol spec: serverInfo, advertise,
subscribe, then binary message data (opcode 1, subscription id, log time, payload)."""

import asyncio
import base64
import json
import socket
import struct
import subprocess

import numpy as np
import pytest
import websockets
from websockets.typing import Subprotocol

from aeb_radar_camera.common.imaging import decode_gray
from aeb_radar_camera.common.net import free_port
from tests.foxglove.protobuf import decode
from tests.recording.publish import HEIGHT, WIDTH, StackPublisher
from tests.support import START_TIMEOUT_S, HealthWatch, ServiceProcess, open_bus, python_module

pytestmark = pytest.mark.slow

IMAGE = "/foxglove/ego/camera/front/image"
ANNOTATIONS = "/foxglove/ego/fusion/primary/annotations/front"
THREAT = "/foxglove/ego/fusion/primary/threat"
HEALTH = "/foxglove/ego/health"
SUBPROTOCOLS = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]


async def receive(port: int, wanted: dict[str, int], timeout_s: float):
    """Connect, subscribe to `wanted` topics as they are advertised, and return
    {topic: [(log time, payload, channel)]} once each has its count."""
    got: dict[str, list] = {t: [] for t in wanted}
    # the opening handshake waits for a bridge a loaded host may not schedule for seconds
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
                                  open_timeout=timeout_s) as ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        channels: dict[int, dict] = {}
        subs: dict[int, int] = {}
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while any(len(got[t]) < n for t, n in wanted.items()):
            # The deadline is the loop's: other topics' messages arriving faster than the
            # wait would otherwise keep a stalled topic waiting for ever.
            try:
                msg = await asyncio.wait_for(ws.recv(), max(0.0, deadline - loop.time()))
            except TimeoutError:
                raise TimeoutError(
                    f"after {timeout_s:g} s: {({t: len(v) for t, v in got.items()})} of "
                    f"{wanted}; advertised {sorted(c['topic'] for c in channels.values())}"
                ) from None
            if isinstance(msg, str):
                data = json.loads(msg)
                if data["op"] == "advertise":
                    for ch in data["channels"]:
                        channels[ch["id"]] = ch
                        if ch["topic"] in wanted:
                            sid = len(subs) + 1
                            subs[sid] = ch["id"]
                            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                                {"id": sid, "channelId": ch["id"]}]}))
            elif msg[0] == 0x01:          # message data: sub id, log time, payload
                sid, log_ns = struct.unpack_from("<IQ", msg, 1)
                ch = channels[subs[sid]]
                got[ch["topic"]].append((log_ns, msg[13:], ch))
    return got


def start_bridge(router, tmp_path, *extra):
    port = free_port()
    proc = ServiceProcess("foxglove", python_module(
        "aeb_radar_camera.tools.cli", "foxglove", "--connect", router, "--port", str(port),
        *extra), tmp_path)
    return proc, port


def test_a_client_subscribes_to_camera_and_annotations_and_decodes_them(router, tmp_path):
    proc, port = start_bridge(router, tmp_path)
    try:
        with open_bus(router, source="test") as bus:
            HealthWatch(bus).wait_alive("foxglove", str(proc.pid), START_TIMEOUT_S)
            pub = StackPublisher(bus).start()
            try:
                got = asyncio.run(receive(port, {IMAGE: 10, ANNOTATIONS: 5, THREAT: 5,
                                                 HEALTH: 1}, 60))
            finally:
                pub.close()
    finally:
        proc.stop()
    ch = got[IMAGE][0][2]
    assert ch["encoding"] == "protobuf" and ch["schemaName"] == "foxglove.CompressedImage"
    schema = base64.b64decode(ch["schema"])
    images = [decode("foxglove.CompressedImage", schema, p) for _, p, _ in got[IMAGE]]
    assert all(im.format == "jpeg" and im.frame_id == "front" for im in images)
    assert decode_gray(images[0].data).shape == (HEIGHT, WIDTH)
    stamps = {im.timestamp.seconds * 10**9 + im.timestamp.nanos for im in images}
    ann_ch = got[ANNOTATIONS][0][2]
    assert ann_ch["schemaName"] == "foxglove.ImageAnnotations"
    ann_schema = base64.b64decode(ann_ch["schema"])
    for _, p, _ in got[ANNOTATIONS]:
        ann = decode("foxglove.ImageAnnotations", ann_schema, p)
        (box,), (label,) = ann.points, ann.texts
        assert [(q.x, q.y) for q in box.points] == [(400, 200), (440, 200), (440, 290),
                                                    (400, 290)]
        assert label.text.startswith("#1 12.0 m TTC 2.4 s edge_density 0.08 verified")
        # Stamped with the frame it was checked in: Foxglove pairs them by timestamp.
        stamp = ann.points[0].timestamp.seconds * 10**9 + ann.points[0].timestamp.nanos
        assert stamp in stamps or stamp < min(stamps)
    threat = json.loads(got[THREAT][0][1])
    assert got[THREAT][0][2]["encoding"] == "json"
    assert threat["track_id"] == 1 and threat["threshold"] == 0.025
    health = json.loads(got[HEALTH][-1][1])
    assert {"service": "foxglove", "instance": str(proc.pid)} in [
        {k: s[k] for k in ("service", "instance")} for s in health["services"]]


def test_max_fps_and_scale_downsample_the_camera(router, tmp_path):
    proc, port = start_bridge(router, tmp_path, "--max-fps", "5", "--scale", "0.5")
    try:
        with open_bus(router, source="test") as bus:
            HealthWatch(bus).wait_alive("foxglove", str(proc.pid), START_TIMEOUT_S)
            pub = StackPublisher(bus).start()
            try:
                got = asyncio.run(receive(port, {IMAGE: 6, ANNOTATIONS: 3}, 60))
            finally:
                pub.close()
    finally:
        proc.stop()
    schema = base64.b64decode(got[IMAGE][0][2]["schema"])
    images = [decode("foxglove.CompressedImage", schema, p) for _, p, _ in got[IMAGE]]
    assert decode_gray(images[0].data).shape == (HEIGHT // 2, WIDTH // 2)
    times = np.array([t for t, _, _ in got[IMAGE]])
    assert np.diff(times).min() >= 190e6          # 5 fps at most, 200 ms apart
    ann = decode("foxglove.ImageAnnotations", base64.b64decode(got[ANNOTATIONS][0][2]["schema"]),
                 got[ANNOTATIONS][0][1])
    corner = ann.points[0].points[0]
    assert (corner.x, corner.y) == (200, 100)


def test_a_port_in_use_is_exit_2_saying_so_before_any_bus(tmp_path):
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        done = subprocess.run(python_module(
            "aeb_radar_camera.tools.cli", "foxglove", "--port", str(port), "--connect",
            f"tcp/127.0.0.1:{free_port()}"), capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    assert f"127.0.0.1:{port} is in use" in done.stderr and "--port" in done.stderr
