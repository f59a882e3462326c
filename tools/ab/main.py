"""`aeb ab-report`: where a primary and a candidate fusion instance disagreed.

Both instances run on the same radar and camera inputs (shadow mode: the brake follows
only the primary). This command pairs their outputs by radar cycle and reports every
disagreement: the command's decision, and per track the verification and decision.

    aeb ab-report --duration 60                        # live, then the report
    aeb ab-report --duration 600 --record ab.mcap      # also keep what was received
    aeb ab-report --from drive.mcap                    # the report of a recording
    aeb ab-report --from drive.mcap --json

Recordings are MCAP (`aeb record`, or `--record` here: the two instances' targets and
commands, as every recorder writes them). A file that is not one, or one that holds no
output of either instance, is an error (exit 2), never an empty report.
"""

import argparse
import json
import sys
import threading
from dataclasses import asdict
from typing import Any

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS, KeySpec
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.ab.compare import Comparator, Report, render
from aeb_radar_camera.tools.ab.feeder import Feeder
from aeb_radar_camera.tools.bus import add_bus_args, open_bus
from aeb_radar_camera.tools.recording.format import channel_of_topic, publish_time

# mcap's reader and writer are imported where they are used: `--help` needs no extra

SPECS: dict[str, KeySpec[Any]] = {s.name: s for s in (FUSION_TARGETS, FUSION_BRAKE_CMD)}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb ab-report", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_bus_args(parser)
    parser.add_argument("--primary", default="primary")
    parser.add_argument("--candidate", default="candidate")
    parser.add_argument("--duration", type=float, default=None,
                        help="listen this long (default: until Ctrl-C)")
    parser.add_argument("--record", default="", help="also write what was received here")
    parser.add_argument("--from", dest="source", nargs="+", default=None,
                        help="report on a recording (MCAP file(s) or a folder)")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--episodes", type=int, default=20, help="episodes to list")
    return parser.parse_args(argv)


def report_json(report: Report, undecodable: int) -> str:
    data = asdict(report)
    data["kinds"] = dict(report.kinds)
    data["verification"] = {f"{a}->{b}": n for (a, b), n in report.verification.items()}
    data["undecodable"] = undecodable
    return json.dumps(data)


def listen(args: argparse.Namespace, feeder: Feeder) -> None:
    """Raises SystemExit(2) when the bus cannot be opened."""
    stop = stop_event_on_signals()
    bus = open_bus(args, "ab-report", stop)
    from aeb_radar_camera.tools.recording.writer import RecordingWriter

    record = RecordingWriter(args.record, metadata={"vehicle": args.vehicle,
                                                    "recorder": "aeb ab-report"}) \
        if args.record else None
    write_lock = threading.Lock()
    try:
        with bus:
            for spec in SPECS.values():
                for instance in (args.primary, args.candidate):
                    def on_raw(payload: bytes, key: str, _rx: int,
                               spec: KeySpec[Any] = spec) -> None:
                        # One lock for both: the recording keeps the order fed, so that
                        # its report is this report.
                        with write_lock:
                            if record is not None:
                                now = wall_ns()
                                record.write(key, channel_of_topic(key), payload, now,
                                             publish_time(payload, now))
                            feeder.feed(spec.name, payload)

                    bus.subscribe_raw(spec, on_raw, instance=instance)
            stop.wait(args.duration)
    finally:
        if record is not None:
            record.close()


def read_recording(args: argparse.Namespace, feeder: Feeder) -> None:
    """Feed both instances' recorded outputs in recorded order. Raises RecordingError
    for what is not a recording, and for one without output of either instance."""
    from aeb_radar_camera.tools.recording.reader import Recording, RecordingError

    rec = Recording.open(args.source)
    vehicle = rec.metadata().get("vehicle", args.vehicle)
    topics = {spec.key(vehicle, instance=inst): spec.name for spec in SPECS.values()
              for inst in (args.primary, args.candidate)}
    channels = rec.channels()
    for inst in (args.primary, args.candidate):
        if not any(channels.get(t) and channels[t].messages for t, _ in _of(topics, inst)):
            raise RecordingError(
                f"{', '.join(map(str, rec.files))} holds no output of fusion instance "
                f"{inst!r} (its keys: {', '.join(t for t, _ in _of(topics, inst))})")
    for r in rec.records(topics):
        feeder.feed(topics[r.topic], r.data)


def _of(topics: dict[str, str], instance: str) -> list[tuple[str, str]]:
    return [(t, n) for t, n in topics.items() if t.split("/")[3] == instance]


def main(argv: list[str] | None = None) -> int:
    """Returns 0, or 2 for what is not a recording (or holds neither instance's output)
    and for a bus that cannot be opened."""
    args = parse_args(argv)
    setup_logging("ab-report", args.log_level)
    try:
        comparator = Comparator(args.primary, args.candidate)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    feeder = Feeder(comparator)
    if args.source:
        from aeb_radar_camera.tools.recording.reader import RecordingError

        try:
            read_recording(args, feeder)
        except RecordingError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    else:
        listen(args, feeder)
    report = comparator.report()
    if args.json:
        print(report_json(report, feeder.undecodable))
    else:
        print(render(report, args.episodes))
        if feeder.undecodable:
            print(f"undecodable payloads skipped: {feeder.undecodable}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
