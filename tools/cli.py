"""`aeb <command> ...`: one entry point; each command lives in its own module.

Commands are imported lazily so that `aeb brake` never pays for OpenCV.
"""

import importlib
import sys

COMMANDS: dict[str, tuple[str, str]] = {
    "radar": ("services.radar.main", "radar service: ARS408 on CAN to tracks on Zenoh"),
    "camera": ("services.camera.main", "camera service: frames to JPEG on Zenoh"),
    "fusion": ("services.fusion.main", "fusion service: verify tracks in the image, decide"),
    "brake": ("services.brake.main", "brake service: commands to the actuator, fail-safe"),
    "sim-actuator": ("tools.sim.actuator", "simulated brake actuator on a serial port"),
    "calib-check": ("tools.calib_check", "draw projected radar tracks over a frame (PNG)"),
    "router": ("common.router", "a Zenoh router"),
    "up": ("tools.launch.main", "start the router and services of a process table"),
    "demo": ("tools.demo", "closed-loop demo on simulated scenarios"),
    "monitor": ("tools.monitor.main", "live view of tracks, targets, brake state, health"),
    "ab-report": ("tools.ab.main", "where a primary and a candidate fusion disagreed"),
    "bench": ("benchmarks.suite", "the benchmark suite"),
    "record": ("tools.recording.record", "record the bus into MCAP (opens in Foxglove)"),
    "replay": ("tools.recording.replay", "publish a recording back on the bus"),
    "rerun": ("tools.recording.rerun", "re-run fusion or radar on a recording, offline"),
    "evidence": ("tools.recording.evidence", "a folder of evidence per WARNING and BRAKE"),
    "foxglove": ("tools.foxglove.bridge", "live view of the bus in Foxglove (WebSocket)"),
}


def usage() -> str:
    lines = ["usage: aeb <command> [options]", "", "commands:"]
    lines += [f"  {name:<13} {doc}" for name, (_, doc) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] in ("-h", "--help"):
        print(usage())
        return 0
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        print(f"error: unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    result = module.main(rest)
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
