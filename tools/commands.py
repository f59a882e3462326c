"""The command table: every `aeb <command>`, the module whose `main(argv)` runs it, and
the extra (pyproject.toml) that installs what it needs beyond the base install.

Modules are named, not imported: `aeb` (tools/cli.py) imports the one it runs, and
`aeb up` (tools/launch/) checks a process table's `aeb` commands against the names.
"""

PACKAGE = "aeb_radar_camera"     # the installed name of common/, services/, tools/
_P = PACKAGE + "."

COMMANDS: dict[str, tuple[str, str]] = {
    "radar": (_P + "services.radar.main", "radar service: ARS408 on CAN to tracks on Zenoh"),
    "camera": (_P + "services.camera.main", "camera service: frames to JPEG on Zenoh"),
    "fusion": (_P + "services.fusion.main", "fusion service: verify tracks in the image, decide"),
    "brake": (_P + "services.brake.main", "brake service: commands to the actuator, fail-safe"),
    "vehicle": (_P + "services.vehicle.main",
                "vehicle gateway: the car's CAN via its DBC to its state"),
    "sim-actuator": (_P + "tools.sim.actuator", "simulated brake actuator on a serial port"),
    "calib-check": (_P + "tools.calib.check", "draw projected radar tracks over a frame (PNG)"),
    "calib-capture": (_P + "tools.calib.capture", "save a frame and its nearest radar cycle"),
    "router": (_P + "common.router", "a Zenoh router"),
    "up": (_P + "tools.launch.main", "start the router and services of a process table"),
    "demo": (_P + "tools.demo", "closed-loop demo on simulated scenarios"),
    "grid": (_P + "tools.grid.main", "Euro NCAP-style test grid, scored, with heat maps"),
    "faults": (_P + "tools.faults.main", "inject faults into the stack, check responses; fuzz"),
    "monitor": (_P + "tools.monitor.main", "live view of tracks, targets, brake state, health"),
    "ab-report": (_P + "tools.ab.main", "where a primary and a candidate fusion disagreed"),
    "bench": ("benchmarks.suite", "the benchmark suite (from a checkout: not installed)"),
    "record": (_P + "tools.recording.record", "record the bus into MCAP (opens in Foxglove)"),
    "info": (_P + "tools.recording.info", "what a recording holds: channels, counts, rates, drops"),
    "replay": (_P + "tools.recording.replay", "publish a recording back on the bus"),
    "rerun": (_P + "tools.recording.rerun", "re-run fusion or radar on a recording, offline"),
    "evidence": (_P + "tools.recording.evidence", "a folder of evidence per WARNING and BRAKE"),
    "foxglove": (_P + "tools.foxglove.bridge", "live view of the bus in Foxglove (WebSocket)"),
    "init": (_P + "tools.init", "write an editable copy of deploy/ for a vehicle"),
    "keygen": (_P + "tools.keygen", "make the BrakeCommand key of a fusion instance"),
    "schemas": (_P + "tools.schemas", "JSON schemas of every message on the bus"),
    "list": (_P + "tools.topics.list_keys", "the keys being published: types, publishers, rates"),
    "nodes": (_P + "tools.topics.nodes", "the services and instances up (liveliness tokens)"),
    "echo": (_P + "tools.topics.echo",
             "print the decoded messages of a key (JSON lines or a table)"),
    "hz": (_P + "tools.topics.hz", "publish rate of a key: mean, min, max and std of the period"),
    "can-export": (_P + "tools.can_export", "a CAN log decoded to CSV with the shipped DBC"),
    "eval": (_P + "tools.eval.cli", "evaluate verifiers on labelled ROIs (the paper's tables)"),
    "label": (_P + "tools.eval.labelweb", "label ROIs YES / NO in a local web page"),
    "train-verifier": (_P + "tools.eval.train_verifier",
                       "train the hog_linear verifier on labelled ROIs"),
}


# The extra (pyproject.toml) that installs what a command needs beyond the base install,
# and the modules of those optional dependencies
COMMAND_EXTRA = {"radar": "radar", "camera": "camera", "fusion": "fusion", "can-export": "dbc",
                 "vehicle": "vehicle",
                 "calib-check": "fusion", "monitor": "monitor", "demo": "demo", "bench": "demo",
                 "faults": "demo", "grid": "demo",
                 "record": "record", "info": "record", "replay": "record", "rerun": "record",
                 "evidence": "record", "foxglove": "record", "ab-report": "record",
                 "eval": "eval", "label": "eval", "train-verifier": "eval"}
OPTIONAL_MODULES = {"can": "radar", "numpy": "radar", "cv2": "camera", "simplejpeg": "camera",
                    "zstandard": "camera", "matplotlib": "demo", "cantools": "dbc",
                    "pyrealsense2": "realsense", "mcap": "record", "foxglove": "record",
                    "dask": "eval", "distributed": "eval"}

# The commands that serve a page or a socket, and their default ports: apart, so that
# both can run at once (Foxglove's own default for its WebSocket protocol is 8765).
DEFAULT_PORTS = {"foxglove": 8765, "label": 8780}


def port_in_use(command: str, host: str, port: int) -> str:
    """What to tell a user whose `aeb <command>` found `host:port` taken."""
    other = next((name for name, p in DEFAULT_PORTS.items()
                  if p == port and name != command), None)
    who = (f"the default port of aeb {other}: is an `aeb {other}` running?" if other
           else "by another program, or another aeb " + command)
    return (f"{host}:{port} is in use ({who}); choose another with --port "
            f"(0: any free port)")
