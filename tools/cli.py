"""`aeb <command> ...`: one entry point; each command lives in its own module.

Commands are imported lazily so that `aeb brake` never pays for OpenCV.
"""

import importlib
import importlib.metadata
import os
import sys

COMMANDS: dict[str, tuple[str, str]] = {
    "radar": ("services.radar.main", "radar service: ARS408 on CAN to tracks on Zenoh"),
    "camera": ("services.camera.main", "camera service: frames to JPEG on Zenoh"),
    "fusion": ("services.fusion.main", "fusion service: verify tracks in the image, decide"),
    "brake": ("services.brake.main", "brake service: commands to the actuator, fail-safe"),
    "sim-actuator": ("tools.sim.actuator", "simulated brake actuator on a serial port"),
    "calib-check": ("tools.calib_check", "draw projected radar tracks over a frame (PNG)"),
    "calib-capture": ("tools.calib_capture", "save a frame and its nearest radar cycle"),
    "router": ("common.router", "a Zenoh router"),
    "up": ("tools.launch.main", "start the router and services of a process table"),
    "demo": ("tools.demo", "closed-loop demo on simulated scenarios"),
    "faults": ("tools.faults.main", "inject faults into the stack, check responses; fuzz"),
    "monitor": ("tools.monitor.main", "live view of tracks, targets, brake state, health"),
    "ab-report": ("tools.ab.main", "where a primary and a candidate fusion disagreed"),
    "bench": ("benchmarks.suite", "the benchmark suite"),
    "record": ("tools.recording.record", "record the bus into MCAP (opens in Foxglove)"),
    "replay": ("tools.recording.replay", "publish a recording back on the bus"),
    "rerun": ("tools.recording.rerun", "re-run fusion or radar on a recording, offline"),
    "evidence": ("tools.recording.evidence", "a folder of evidence per WARNING and BRAKE"),
    "foxglove": ("tools.foxglove.bridge", "live view of the bus in Foxglove (WebSocket)"),
    "init": ("tools.init", "write an editable copy of deploy/ for a vehicle"),
    "keygen": ("tools.keygen", "make the BrakeCommand key of a fusion instance"),
    "schemas": ("tools.schemas", "JSON schemas of every message on the bus"),
    "echo": ("tools.topics.echo", "print the decoded messages of a key (JSON lines or a table)"),
    "hz": ("tools.topics.hz", "publish rate of a key: mean, min, max and std of the period"),
    "can-export": ("tools.can_export", "a CAN log decoded to CSV with the shipped DBC"),
    "eval": ("tools.eval.cli", "evaluate verifiers on labelled ROIs (the paper's tables)"),
    "label": ("tools.eval.labelweb", "label ROIs YES / NO in a local web page"),
    "train-verifier": ("tools.train_verifier", "train the hog_linear verifier on labelled ROIs"),
}


# The extra (pyproject.toml) that installs what a command needs beyond the base install,
# and the modules of those optional dependencies
COMMAND_EXTRA = {"radar": "radar", "camera": "camera", "fusion": "fusion", "can-export": "dbc",
                 "calib-check": "fusion", "monitor": "monitor", "demo": "demo", "bench": "demo",
                 "faults": "demo",
                 "record": "record", "replay": "record", "rerun": "record",
                 "evidence": "record", "foxglove": "record"}
OPTIONAL_MODULES = {"can": "radar", "numpy": "radar", "cv2": "camera", "simplejpeg": "camera",
                    "matplotlib": "demo", "cantools": "dbc", "pyrealsense2": "realsense",
                    "mcap": "record", "foxglove": "record"}


DISTRIBUTION = "aeb-radar-camera"


def version() -> str:
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:   # run from a checkout, not installed
        return "unknown (not installed)"


def usage() -> str:
    lines = ["usage: aeb <command> [options]    (aeb --version; aeb <command> --help)", "",
             "commands:"]
    lines += [f"  {name:<13} {doc}" for name, (_, doc) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] in ("-h", "--help"):
        print(usage())
        return 0
    if args[0] in ("-V", "--version"):
        print(f"aeb {version()} ({DISTRIBUTION}, Python {sys.version.split()[0]})")
        return 0
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        print(f"error: unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(COMMANDS[name][0])
    except ModuleNotFoundError as exc:
        missing = (exc.name or "").split(".")[0]
        if missing not in OPTIONAL_MODULES:
            raise
        extra = COMMAND_EXTRA.get(name, OPTIONAL_MODULES[missing])
        print(f"error: aeb {name} needs the Python package {exc.name!r}, which is not "
              f"installed: pip install 'aeb-radar-camera[{extra}]'", file=sys.stderr)
        return 2
    try:
        result = module.main(rest)
    except BrokenPipeError:   # the reader went away (`aeb echo KEY | head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
