import threading

import pytest

from aeb_radar_camera.common.bus import Bus, BusError, zenoh_config
from aeb_radar_camera.common.config.base import ZenohSettings
from aeb_radar_camera.common.keys import BRAKE_STATUS, FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import Decision, VerifierStatus, decode, encode
from aeb_radar_camera.common.messages.fusion import BrakeCommand
from aeb_radar_camera.common.messages.header import Header
from tests.support import Collector, HealthWatch, open_bus, wait_for


def cmd(seq: int) -> BrakeCommand:
    return BrakeCommand(
        header=Header(seq=seq, source="test", stamp_ns=1, pub_mono_ns=2), instance="primary",
        decision=Decision.NONE, brake_level_pct=0.0, verifier_status=VerifierStatus.OK,
        held=False, track_id=-1, range_m=None, ttc_s=None, reason="", radar_seq=seq,
        radar_last_frame_mono_ns=0,
    )


def test_config_keeps_multicast_off_and_applies_overrides():
    import json
    conf = zenoh_config(ZenohSettings(overrides={"transport/unicast/max_links": 2}))
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("transport/unicast/max_links")) == 2
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]


def test_bad_override_and_missing_file_are_bus_errors():
    with pytest.raises(BusError, match="invalid zenoh configuration"):
        zenoh_config(ZenohSettings(overrides={"no/such/key": 1}))
    with pytest.raises(BusError, match="not found"):
        zenoh_config(ZenohSettings(config_file="/nonexistent.json5"))
    with pytest.raises(BusError, match="invalid zenoh configuration"):   # not JSON
        zenoh_config(ZenohSettings(overrides={"transport/unicast/max_links": {1, 2}}))


def test_a_port_already_taken_is_a_bus_error():
    import socket

    from aeb_radar_camera.common.bus import open_session
    from aeb_radar_camera.common.config.base import ZenohMode

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(BusError, match="cannot open zenoh session"):
            open_session(ZenohSettings(mode=ZenohMode.PEER, connect=(),
                                       listen=(f"tcp/127.0.0.1:{port}",)))


def test_a_failing_callback_is_counted_and_later_samples_still_arrive(router):
    with open_bus(router, source="pub") as pub_bus, open_bus(router, source="sub") as sub_bus:
        got: list[int] = []
        raw: list[str] = []

        def picky(msg: BrakeCommand, key: str) -> None:
            if msg.header.seq == 1:
                raise RuntimeError("a bug in the subscriber")
            got.append(msg.header.seq)

        def picky_raw(payload: bytes, key: str, rx_mono_ns: int) -> None:
            raw.append(key)
            if len(raw) == 2:
                raise RuntimeError("a bug in the raw subscriber")

        sub_bus.subscribe(FUSION_BRAKE_CMD, picky, instance="primary")
        sub_bus.subscribe_raw(BRAKE_STATUS, picky_raw)
        pub = pub_bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        status_key = pub_bus.key(BRAKE_STATUS)

        def first_samples() -> bool:    # until both subscriptions have propagated
            pub.put(cmd(0))
            if not raw:
                pub_bus.session.put(status_key, b"x")
            return bool(got) and bool(raw)

        wait_for(first_samples, 30, 0.05, "first samples")
        pub.put(cmd(1))
        pub.put(cmd(2))
        pub_bus.session.put(status_key, b"x")
        pub_bus.session.put(status_key, b"x")
        wait_for(lambda: 2 in got and len(raw) >= 3, 10, 0.02, "samples after the failures")
        assert 1 not in got
        assert sub_bus.callback_errors.get("fusion_brake_cmd") == 1
        assert sub_bus.callback_errors.get("brake_status") == 1


def test_publish_subscribe_through_a_router_and_count_garbage(router):
    with open_bus(router, source="pub") as pub_bus, open_bus(router, source="sub") as sub_bus:
        got = Collector()
        sub_bus.subscribe(FUSION_BRAKE_CMD, got, instance="primary")
        other = Collector()
        sub_bus.subscribe(FUSION_BRAKE_CMD, other, instance="candidate")
        pub = pub_bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        # The subscription may take a moment to propagate through the router.
        def first_sample() -> int:
            pub.put(cmd(0))
            return len(got.items)

        wait_for(first_sample, 30, 0.05, "first sample")
        n = len(got.items)
        pub_bus.session.put(pub.key, b"\x00garbage")
        pub.put(cmd(1))
        # a late copy of cmd(0) from the loop above may arrive first: wait for cmd(1)
        wait_for(lambda: any(m.header.seq == 1 for m in got.messages[n:]), 10)
        wait_for(lambda: sub_bus.decode_errors.get("fusion_brake_cmd") == 1, 10)
        assert got.messages[-1].header.seq == 1
        assert got.items[-1][1] == "aeb/ego/fusion/primary/brake_cmd"
        assert other.items == []


def test_liveliness_appears_and_vanishes(router):
    with open_bus(router) as watcher_bus:
        watch = HealthWatch(watcher_bus)
        with open_bus(router) as svc:
            token = svc.declare_health("fusion", "primary")
            watch.wait_alive("fusion", "primary", 30)
            token.undeclare()
            wait_for(lambda: not watch.is_alive("fusion", "primary"), 30)


def test_client_started_before_its_router_connects_when_it_appears(tmp_path):
    from tests.support import free_port, router_process

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    opened: dict[str, Bus] = {}
    t = threading.Thread(target=lambda: opened.setdefault("bus", open_bus(endpoint)))
    t.start()
    assert not opened  # blocked: nothing listens yet
    with router_process(tmp_path, port):
        t.join(60)
        assert "bus" in opened
        with opened["bus"] as bus, open_bus(endpoint) as other:
            got = Collector()
            bus.subscribe(BRAKE_STATUS, got)
            assert got.items == []
            def garbage_counted() -> int:
                other.session.put(bus.key(BRAKE_STATUS), b"x")
                return bus.decode_errors.get("brake_status")

            wait_for(garbage_counted, 30, 0.05)


def test_queryable_answers_typed_queries_and_failures_are_counted(router):
    """Bus.declare_queryable / Bus.query (added for CameraInfo)."""
    from aeb_radar_camera.common.keys import CAMERA_INFO
    from aeb_radar_camera.common.messages import CameraInfo

    def info(camera: str) -> CameraInfo:
        return CameraInfo(
            header=Header(seq=0, source=f"camera/{camera}", stamp_ns=1, pub_mono_ns=2),
            camera=camera, width=848, height=480, k=(1.0,) * 9, dist=(), r=(1.0,) * 9,
            t_m=(0.0,) * 3, fps=30.0, source="folder", frames_published=0,
            frames_dropped=0, read_errors=0, healthy=True, status="")

    def broken() -> CameraInfo:
        raise RuntimeError("no calibration")

    with open_bus(router, source="srv") as srv, open_bus(router, source="cli") as cli:
        q1 = srv.declare_queryable(CAMERA_INFO, lambda: info("front"), camera="front")
        q2 = srv.declare_queryable(CAMERA_INFO, broken, camera="rear")
        try:
            replies = wait_for(lambda: cli.query(CAMERA_INFO, 5.0, camera="front"), 30)
            assert [(m.camera, key) for m, key in replies] == [
                ("front", "aeb/ego/camera/front/info")]
            # Wildcard: the good reply arrives, the failing one is counted on both sides.
            seen: list[list[str]] = []

            def wildcard_saw_the_failure() -> bool:
                seen.append([m.camera for m, _ in cli.query(CAMERA_INFO, 5.0)])
                return cli.decode_errors.get("camera_info") >= 1

            wait_for(wildcard_saw_the_failure, 30)
            assert seen[-1] == ["front"]
            assert srv.callback_errors.get("camera_info") == cli.decode_errors.get("camera_info")
        finally:
            q1.undeclare()
            q2.undeclare()


def test_queued_subscription_keeps_samples_until_drained_and_counts_garbage(router):
    with open_bus(router, source="pub") as pub_bus, open_bus(router, source="sub") as sub_bus:
        with pytest.raises(ValueError, match="capacity"):
            sub_bus.subscribe_queued(FUSION_BRAKE_CMD, 0, instance="primary")
        queued = sub_bus.subscribe_queued(FUSION_BRAKE_CMD, 64, instance="primary")
        pub = pub_bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        drained: list[tuple[BrakeCommand, str]] = []

        def drain() -> list[int]:
            drained.extend(sub_bus.drain_queued(FUSION_BRAKE_CMD, queued))
            return [m.header.seq for m, _ in drained]

        def first_sample() -> bool:   # until the subscription has propagated
            pub.put(cmd(0))
            return bool(drain())

        wait_for(first_sample, 30, 0.05, "first queued sample")
        # through the same publisher: Zenoh keeps the order within one priority only
        pub.put_bytes(b"\x00garbage")
        for seq in (101, 102, 103):
            pub.put(cmd(seq))
        wait_for(lambda: drain()[-3:] == [101, 102, 103], 10, 0.02, "three queued samples")
        assert all(k == "aeb/ego/fusion/primary/brake_cmd" for _, k in drained)
        # in order, and the garbage (published before 101) was drained: counted, left out
        assert sub_bus.decode_errors.get("fusion_brake_cmd") == 1
        assert sub_bus.drain_queued(FUSION_BRAKE_CMD, queued) == []
        queued.undeclare()


def test_put_bytes_publishes_the_payload_unchanged(router):
    with open_bus(router, source="pub") as pub_bus, open_bus(router, source="sub") as sub_bus:
        got: list[bytes] = []
        sub_bus.subscribe_raw(FUSION_BRAKE_CMD, lambda p, k, t: got.append(p),
                              instance="primary")
        pub = pub_bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        data = encode(cmd(5))

        def seen() -> bool:
            pub.put_bytes(data)
            return bool(got)

        wait_for(seen, 30, 0.05, "the raw payload")
        assert got[0] == data and decode(got[0], BrakeCommand).header.seq == 5


def test_every_sample_carries_its_message_encoding(router):
    """What `z_sub`, a bridge or a recorder sees: msgpack with the message type as schema,
    on published samples and on query replies alike."""
    from aeb_radar_camera.common.keys import CAMERA_INFO
    from tests.messages_support import example

    with open_bus(router, source="pub") as pub_bus, open_bus(router, source="sub") as sub_bus:
        encodings: list[str] = []
        raw = sub_bus.session.declare_subscriber(
            "aeb/ego/**", lambda s: encodings.append(str(s.encoding)))
        pub = pub_bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        status = pub_bus.publisher(BRAKE_STATUS)

        def both_seen() -> bool:
            pub.put(cmd(1))
            status.put(example(BRAKE_STATUS.msg_type))
            return len(set(encodings)) >= 2

        wait_for(both_seen, 30, 0.05, "samples of both keys")
        assert set(encodings) == {"application/msgpack;aeb.BrakeCommand",
                                  "application/msgpack;aeb.BrakeStatus"}
        q = pub_bus.declare_queryable(CAMERA_INFO, lambda: example(CAMERA_INFO.msg_type),
                                      camera="front")
        try:
            def reply_encoding() -> str:
                for reply in sub_bus.session.get("aeb/ego/camera/front/info", timeout=5.0):
                    if reply.ok is not None:
                        return str(reply.ok.encoding)
                return ""

            assert wait_for(reply_encoding, 30) == "application/msgpack;aeb.CameraInfo"
        finally:
            q.undeclare()
            raw.undeclare()
