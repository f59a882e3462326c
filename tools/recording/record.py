"""`aeb record`: everything on the vehicle's bus (or a selection of keys) into MCAP, with
the Foxglove views derived beside it (tools/recording/format.py has the layout).

    aeb record                                            # aeb_2026_12_02-15_18_08.mcap
    aeb record -o drive.mcap                              # every key, this host's router
    aeb record -o drive.mcap --connect tcp/192.168.10.1:7447
    aeb record -o drives/run.mcap --split-size 2000 --split-duration 600
    aeb record -o fusion.mcap --keys radar_tracks,camera_jpeg,fusion/primary/*
    aeb record -o drive.mcap --evidence evidence/         # + a folder per WARNING/BRAKE

The raw CAN frames are recorded when the radar publishes them (`[radar.raw_can]`), or
read here from a CAN interface with `--can socketcan:can0`.

The recorder (tools/recording/recorder.py) reads each subscription on its own thread and
writes on one more. Ctrl-C or SIGTERM ends it with a complete file
(summary and index); a recorder that is killed leaves the chunks written so far
readable. On exit it says what it wrote: messages and bytes per key, and how many
messages each key's sequence numbers say never arrived.

An existing file is never overwritten (as rosbag2: choose another name or remove it);
without `-o` the file is named by the local date and time it starts.

Exit codes: 0 after a signal or --duration, 2 for bad arguments, an existing output or no
bus.
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, open_bus, run_until

if TYPE_CHECKING:
    from aeb_radar_camera.tools.recording.recorder import RecordStats


def summary_text(stats: "RecordStats") -> str:
    minutes = max(1e-9, (stats.ended_ns - stats.started_ns) / 60e9)
    lines = [f"wrote {len(stats.files)} file(s), {stats.bytes_on_disk / 1e6:.1f} MB in "
             f"{minutes * 60:.1f} s ({stats.bytes_on_disk / 1e6 / minutes:.1f} MB/min): "
             + ", ".join(stats.files),
             f"{'key':<44} {'messages':>9} {'MB':>9} {'dropped':>7} {'undecodable':>12}"]
    for key, s in sorted(stats.keys.items()):
        lines.append(f"{key:<44} {s.messages:>9} {s.bytes / 1e6:>9.2f} {s.dropped:>7} "
                     f"{s.undecodable:>12}")
    total = sum(s.messages for s in stats.keys.values())
    dropped = sum(s.dropped for s in stats.keys.values())
    lines.append(f"{'total':<44} {total:>9} {sum(s.bytes for s in stats.keys.values()) / 1e6:>9.2f}"
                 f" {dropped:>7} {sum(s.undecodable for s in stats.keys.values()):>12}")
    lines.append(f"derived Foxglove messages: {stats.derived}"
                 + (f" ({stats.derived_errors} could not be derived)"
                    if stats.derived_errors else ""))
    lines.append("dropped: messages the publisher numbered, between the first and the last "
                 "recorded, that never reached the recorder")
    return "\n".join(lines)


def default_name(now_s: float) -> str:
    """The file a recording started at `now_s` (epoch seconds) gets without `-o`: its
    local date and time, as rosbag2 names its bags."""
    return time.strftime("aeb_%Y_%m_%d-%H_%M_%S.mcap", time.localtime(now_s))


def existing_outputs(out: Path, split: bool) -> list[Path]:
    """The files a recording into `out` would overwrite: `out` itself, or with splitting
    any `<stem>_NNNN.mcap` beside it."""
    if not split:
        return [out] if out.exists() else []
    stem = out.name.removesuffix(".mcap")
    return sorted(out.parent.glob(f"{stem}_[0-9][0-9][0-9][0-9].mcap"))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb record", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--out", default="",
                        help="the MCAP file, never overwritten (default: "
                             "aeb_YYYY_MM_DD-HH_MM_SS.mcap, the start's local time)")
    add_bus_args(parser, connect_timeout_s=0.0)
    parser.add_argument("--keys", default="",
                        help="comma-separated key names or expressions (default: every key)")
    parser.add_argument("--split-size", type=float, default=None, metavar="MB",
                        help="start a new file after this many MB")
    parser.add_argument("--split-duration", type=float, default=None, metavar="S",
                        help="start a new file after this many seconds")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many seconds (default: at Ctrl-C)")
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    parser.add_argument("--no-views", action="store_true",
                        help="only the stack's channels, no derived Foxglove channels")
    parser.add_argument("--fusion-config", default="",
                        help="fusion config whose corridor the scene draws (default: the "
                             "shipped defaults)")
    parser.add_argument("--evidence", default="", metavar="DIR",
                        help="also write an evidence folder per WARNING and BRAKE here")
    parser.add_argument("--can", default="", metavar="INTERFACE:CHANNEL[:BUS]",
                        help="also read raw CAN frames from this python-can interface")
    parser.add_argument("--summary-json", default="", help="write the exit summary here too")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    # after the arguments: `--help` needs no extra installed
    from aeb_radar_camera.tools.recording.foxglove_views import Converter
    from aeb_radar_camera.tools.recording.recorder import (
        RECORDER_STATUS,
        Recorder,
        decision_settings,
        selection,
    )
    from aeb_radar_camera.tools.recording.writer import RecordingWriter

    setup_logging("record", args.log_level)
    stop = stop_event_on_signals()
    out = Path(args.out or default_name(time.time()))
    split = args.split_size is not None or args.split_duration is not None
    existing = existing_outputs(out, split)
    if existing:
        print(f"error: {existing[0]} already exists"
              + (f" (and {len(existing) - 1} more)" if len(existing) > 1 else "")
              + ": aeb record never overwrites a recording; choose another -o or remove it",
              file=sys.stderr)
        return 2
    try:
        exprs = selection(args.keys, args.vehicle)
        converter = None if args.no_views else Converter(
            args.vehicle, decision_settings(args.fusion_config))
        writer = RecordingWriter(
            out, split_bytes=None if args.split_size is None else int(args.split_size * 1e6),
            split_s=args.split_duration, compression=args.compression,
            metadata={"vehicle": args.vehicle, "keys": ",".join(exprs),
                      "recorder": "aeb record"}, exclusive=True)
    except (ValueError, ConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    sinks: list[Any] = []
    if args.evidence:
        from aeb_radar_camera.tools.recording.evidence import EvidenceCollector

        sinks.append(EvidenceCollector(Path(args.evidence), args.vehicle,
                                       decision_settings(args.fusion_config)))
    bus = open_bus(args, "record", stop)
    with bus:
        recorder = Recorder(bus, writer, exprs, converter, tuple(sinks))
        can_reader = None
        try:
            recorder.start()
            if args.can:
                from aeb_radar_camera.tools.recording.can_reader import CanReader

                can_reader = CanReader.from_spec(args.can, args.vehicle, recorder.submit)
                can_reader.start()
        except (ValueError, OSError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            recorder.stop()
            return 2
        # Declared once subscribed: seeing it means the recorder is recording.
        status = bus.declare_queryable(RECORDER_STATUS, recorder.status,
                                       instance=str(os.getpid()))
        token = bus.declare_health("record", str(os.getpid()))
        print(f"recording {', '.join(exprs)} into {out} (Ctrl-C to stop)",
              file=sys.stderr, flush=True)
        run_until(stop, args.duration, lambda: recorder.write_error is not None)
        token.undeclare()
        status.undeclare()
        if can_reader is not None:
            can_reader.stop()
        stats = recorder.stop()
    print(summary_text(stats), file=sys.stderr, flush=True)
    if args.summary_json:
        Path(args.summary_json).write_text(json.dumps(stats.as_json(), indent=1))
    if recorder.write_error is not None:
        print(f"error: writing stopped: {recorder.write_error!r}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
