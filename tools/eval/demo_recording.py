"""`aeb eval record-demo`: the demo scenarios in closed loop (the same session as
`aeb demo`: the real services on a SIMULATED vehicle, radar, camera and actuator),
recorded in the project's MCAP layout for `aeb eval`.

Recorded: radar tracks, camera frames, their depth and CameraInfo, fusion's targets and
brake commands, the brake's status and the simulator's ground truth (`sim/world`), each on
its own channel as the recording layout says, by `aeb record`'s recorder.
"""

import sys
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_DEPTH,
    CAMERA_INFO,
    CAMERA_JPEG,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_TRACKS,
    KeySpec,
)
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.keys import SIM_WORLD
from aeb_radar_camera.tools.recording.recorder import Recorder
from aeb_radar_camera.tools.recording.writer import RecordingWriter

SPECS: tuple[KeySpec[Any], ...] = (RADAR_TRACKS, CAMERA_JPEG, CAMERA_DEPTH, CAMERA_INFO,
                                   FUSION_TARGETS, FUSION_BRAKE_CMD, BRAKE_STATUS, SIM_WORLD)


def record_demo(out: Path, scenarios: str, camera_fps: float,
                fusion_config: Path | None = None) -> int:
    """Run and record the scenarios, fusion configured by `fusion_config` (default: the
    demo's); 0 when recorded (whatever the verdicts), 2 when the stack could not start."""
    from aeb_radar_camera.tools.sim.scenario import DEMO_SCENARIOS, pick_scenarios
    from aeb_radar_camera.tools.sim.session import SETTLE_TIMEOUT_S, StackStartError, closed_loop
    from aeb_radar_camera.tools.sim.stack import FUSION_CONFIG

    chosen = pick_scenarios(scenarios or ",".join(DEMO_SCENARIOS))
    stop = stop_event_on_signals(grace_s=None)
    print("recording a closed-loop SIMULATION (simulated vehicle, radar, camera, actuator; "
          f"the real services) to {out}", file=sys.stderr, flush=True)
    recorder: Recorder | None = None
    try:
        with closed_loop(out.parent / f"{out.stem}-stack", camera_fps=camera_fps,
                         log=sys.stderr, fusion_config=fusion_config or FUSION_CONFIG) as loop:
            recorder = Recorder(loop.bus, RecordingWriter(out, flush_s=None),
                                [spec.wildcard(loop.bus.vehicle) for spec in SPECS],
                                converter=None)
            recorder.start()
            for i, sc in enumerate(chosen, 1):
                if stop.is_set():
                    break
                result = loop.sim.run(sc)
                print(f"[{i}/{len(chosen)}] {sc.name}: {result.verdict.outcome}",
                      file=sys.stderr, flush=True)
                if i < len(chosen) and not loop.sim.wait_settled(SETTLE_TIMEOUT_S):
                    print("  warning: the stack did not settle", file=sys.stderr)
            stats = recorder.stop()
            recorder = None
    except StackStartError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        if recorder is not None:
            recorder.stop()
    total = sum(k.messages for k in stats.keys.values())
    print(f"wrote {out}: {total} messages on {len(stats.keys)} channels")
    for key, k in sorted(stats.keys.items()):
        print(f"  {key}: {k.messages}" + (f" ({k.dropped} never arrived)" if k.dropped else ""))
    return 0
