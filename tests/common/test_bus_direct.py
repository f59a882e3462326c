"""Bus additions for the latency path: callbacks run on Zenoh's receive thread
(`direct`), and raw payloads published with a key's QoS (`put_bytes`)."""

import threading

from common.keys import FUSION_BRAKE_CMD
from common.messages import decode, encode
from common.messages.fusion import BrakeCommand
from tests.common.test_bus import cmd
from tests.support import Collector, open_bus, wait_for


def thread_name() -> str:
    with open(f"/proc/self/task/{threading.get_native_id()}/comm", encoding="utf-8") as f:
        return f.read().strip()


def test_direct_callbacks_run_on_zenohs_receive_thread_and_indirect_ones_do_not(router):
    with open_bus(router, source="pub") as pub_bus, open_bus(router, source="sub") as sub_bus:
        names: dict[str, set[str]] = {"direct": set(), "indirect": set()}
        raw = Collector()

        def on(kind: str):
            def cb(msg, key, *rest) -> None:
                names[kind].add(thread_name())
                raw(msg, key)
            return cb

        sub_bus.subscribe(FUSION_BRAKE_CMD, on("direct"), direct=True, instance="primary")
        sub_bus.subscribe_raw(FUSION_BRAKE_CMD, on("indirect"), instance="primary")
        pub = pub_bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        seq = [0]

        def both_seen() -> bool:
            pub.put(cmd(seq[0]))
            seq[0] += 1
            return bool(names["direct"] and names["indirect"])

        wait_for(both_seen, 30, 0.05, "samples on both subscriptions")
        assert all(n.startswith("rx-") for n in names["direct"]), names
        assert not any(n.startswith("rx-") for n in names["indirect"]), names


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
