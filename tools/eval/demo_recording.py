"""`aeb eval record-demo`: the demo scenarios in closed loop (the same session as
`aeb demo`: the real services on a SIMULATED vehicle, radar, camera and actuator),
recorded in the project's MCAP layout for `aeb eval`.

Recorded: radar tracks, camera frames, their depth and CameraInfo, fusion's targets and
brake commands, the brake's status and the simulator's ground truth (`sim/world`), each on its
own channel as the recording layout says. This is a narrow recorder of the evaluation's
inputs, for machines without a general recorder.
"""

import queue
import sys
import threading
from pathlib import Path
from typing import Any

from common.clock import wall_ns
from common.keys import (
    BRAKE_STATUS,
    CAMERA_DEPTH,
    CAMERA_INFO,
    CAMERA_JPEG,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_TRACKS,
    KeySpec,
)
from common.messages import DecodeError, decode
from common.service import stop_event_on_signals
from tools.eval.mcap_io import RecordingWriter
from tools.sim.messages import SIM_WORLD

SPECS: tuple[KeySpec[Any], ...] = (RADAR_TRACKS, CAMERA_JPEG, CAMERA_DEPTH, CAMERA_INFO,
                                   FUSION_TARGETS, FUSION_BRAKE_CMD, BRAKE_STATUS, SIM_WORLD)


class BusRecorder:
    """Subscribes to SPECS on a bus and writes every sample from one writer thread
    (Zenoh's threads only enqueue)."""

    def __init__(self, path: Path) -> None:
        self.writer = RecordingWriter(path)
        self.counts: dict[str, int] = {}
        self.undecodable = 0
        self._q: queue.Queue[tuple[KeySpec[Any], str, bytes, int] | None] = queue.Queue()
        self._subs: list[Any] = []
        self._thread = threading.Thread(target=self._run, name="eval-recorder", daemon=True)
        self._thread.start()

    def subscribe(self, bus: Any) -> None:
        for spec in SPECS:
            def on_raw(payload: bytes, key: str, rx_mono_ns: int,
                       spec: KeySpec[Any] = spec) -> None:
                self._q.put((spec, key, payload, wall_ns()))

            self._subs.append(bus.subscribe_raw(spec, on_raw))

    def _run(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            spec, key, payload, log_time = item
            assert spec.msg_type is not None
            try:
                msg = decode(payload, spec.msg_type)
            except DecodeError:
                self.undecodable += 1
                continue
            header = getattr(msg, "header", None)
            self.writer.write_raw(key, spec.msg_type, payload, log_time,
                                  header.stamp_ns if header is not None else log_time)
            self.counts[key] = self.counts.get(key, 0) + 1

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._q.put(None)
        self._thread.join()
        self.writer.close()


def record_demo(out: Path, scenarios: str, camera_fps: float,
                fusion_config: Path | None = None) -> int:
    """Run and record the scenarios, fusion configured by `fusion_config` (default: the
    demo's); 0 when recorded (whatever the verdicts), 2 when the stack could not start."""
    from tools.demo import DEMO_SCENARIOS, pick_scenarios
    from tools.sim.session import SETTLE_TIMEOUT_S, StackStartError, closed_loop
    from tools.sim.stack import FUSION_CONFIG

    chosen = pick_scenarios(scenarios or ",".join(DEMO_SCENARIOS))
    stop = stop_event_on_signals(grace_s=None)
    print("recording a closed-loop SIMULATION (simulated vehicle, radar, camera, actuator; "
          f"the real services) to {out}", file=sys.stderr, flush=True)
    recorder = BusRecorder(out)
    try:
        with closed_loop(out.parent / f"{out.stem}-stack", camera_fps=camera_fps,
                         log=sys.stderr, fusion_config=fusion_config or FUSION_CONFIG) as loop:
            recorder.subscribe(loop.bus)
            for i, sc in enumerate(chosen, 1):
                if stop.is_set():
                    break
                result = loop.sim.run(sc)
                print(f"[{i}/{len(chosen)}] {sc.name}: {result.verdict.outcome}",
                      file=sys.stderr, flush=True)
                if i < len(chosen) and not loop.sim.wait_settled(SETTLE_TIMEOUT_S):
                    print("  warning: the stack did not settle", file=sys.stderr)
    except StackStartError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        recorder.close()
    total = sum(recorder.counts.values())
    print(f"wrote {out}: {total} messages on {len(recorder.counts)} channels "
          f"({recorder.undecodable} undecodable)")
    for key, n in sorted(recorder.counts.items()):
        print(f"  {key}: {n}")
    return 0
