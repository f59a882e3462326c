"""`aeb can-export LOG`: a CAN log decoded to CSV with a DBC (cantools reads it), for a
spreadsheet or PlotJuggler.

    aeb can-export drive.log --out drive.csv                 # the shipped ARS408 DBC
    aeb can-export drive.blf --dbc my.dbc --format long      # one row per signal value
    aeb can-export drive.log --only Obj_1_General --only 0x60A --relative-time

LOG: anything python-can's LogReader reads (candump -l .log, .asc, .blf, .trc, .csv, ...).
`--format wide` (default): one row per frame, columns `time_s, channel, can_id, message`
then one column per `Message.Signal` of the DBC, empty where the frame is another
message (PlotJuggler's CSV loader takes `time_s` as its time axis). `--format long`: one
row per signal value, `time_s, channel, can_id, message, signal, value, unit`. Values are
physical (scaled), numeric; `--choices` writes value-table names instead. The shipped
DBC is for SensorID 0; `--sensor-id N` reads a radar with another ID (its IDs are 0x10 * N
higher). Frames the DBC does not know or cannot decode are counted on stderr, never
silently lost. Needs the `dbc` extra (cantools, python-can).

Exit codes: 0 written, 2 unreadable log or DBC, or bad options.
"""

import argparse
import csv
import sys
import time
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.resources import ARS408_DBC

WIDE_HEAD = ["time_s", "channel", "can_id", "message"]
LONG_HEAD = [*WIDE_HEAD, "signal", "value", "unit"]
_PROGRESS_S = 2.0


class ExportError(ValueError):
    """The log, the DBC or an option cannot be used; the message says which."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb can-export", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("log", help="CAN log (candump .log, .asc, .blf, ...)")
    parser.add_argument("--dbc", default=str(ARS408_DBC),
                        help="DBC file (default: the shipped ARS408-21 DBC)")
    parser.add_argument("--out", help="CSV file to write (default: stdout)")
    parser.add_argument("--format", choices=["wide", "long"], default="wide")
    parser.add_argument("--only", action="append", default=[], metavar="MESSAGE",
                        help="export only this message, by name or ID (repeatable)")
    parser.add_argument("--sensor-id", type=int, default=0, choices=range(8), metavar="0..7",
                        help="ARS408 SensorID of the radar in the log (default 0)")
    parser.add_argument("--relative-time", action="store_true",
                        help="time_s from the first frame instead of the log's own clock")
    parser.add_argument("--choices", action="store_true",
                        help="value-table names instead of numbers where the DBC has them")
    add_log_level(parser, "WARNING")
    return parser.parse_args(argv)


def load_dbc(path: str) -> Any:
    """Raises ExportError (cantools missing, unreadable or invalid DBC)."""
    try:
        import cantools
    except ModuleNotFoundError as exc:
        raise ExportError("aeb can-export needs cantools: pip install "
                          "'aeb-radar-camera[dbc]'") from exc
    try:
        db = cantools.database.load_file(path)
    except OSError as exc:
        raise ExportError(f"{path}: cannot read the DBC: {exc}") from exc
    except (cantools.database.UnsupportedDatabaseFormatError, ValueError) as exc:
        # ValueError: a file extension cantools has no parser for
        raise ExportError(f"{path}: not a CAN database cantools reads (DBC, KCD, SYM, "
                          f"ARXML, CDD): {str(exc).strip()}") from exc
    if not isinstance(db, cantools.database.can.Database):
        raise ExportError(f"{path}: not a CAN database")
    return db


def select(db: Any, only: list[str]) -> list[Any]:
    """The DBC's messages to export, in file order. Raises ExportError naming an unknown
    one."""
    if not only:
        return list(db.messages)
    chosen = []
    for item in only:
        try:
            msg = (db.get_message_by_frame_id(int(item, 0)) if item[:1].isdigit()
                   else db.get_message_by_name(item))
        except (KeyError, ValueError) as exc:
            raise ExportError(f"--only {item!r}: no such message in the DBC") from exc
        chosen.append(msg)
    return [m for m in db.messages if m in chosen]


def frames(path: str) -> Iterator[Any]:
    """The log's frames (python-can). Raises ExportError for an unreadable log."""
    import can

    if not Path(path).is_file():
        raise ExportError(f"{path}: no such file")
    try:
        reader = can.LogReader(path)
    except (ValueError, OSError, can.CanError) as exc:
        raise ExportError(f"{path}: cannot read the log: {exc}") from exc
    try:
        yield from reader
    except (ValueError, OSError, can.CanError) as exc:   # a garbled line ends the read
        raise ExportError(f"{path}: unreadable after the frames exported so far: {exc}") \
            from exc


def _value(v: Any) -> Any:
    if isinstance(v, float):
        return f"{v:.10g}"
    return v if isinstance(v, int) else str(v)


class Exporter:
    """Decodes frames with the DBC and writes rows; counts what it could not export."""

    def __init__(self, db: Any, messages: list[Any], sensor_id: int, choices: bool) -> None:
        self.db = db
        self.by_id = {m.frame_id: m for m in messages}
        self.wanted = {m.frame_id for m in messages}
        self.all_ids = {m.frame_id for m in db.messages}
        self.offset = 0x10 * sensor_id
        self.choices = choices
        self.columns = [f"{m.name}.{s.name}" for m in messages for s in m.signals]
        self.exported = 0
        self.skipped: Counter[str] = Counter()   # reason -> frames

    def decoded(self, msgs: Iterable[Any], relative: bool) -> Iterator[tuple[Any, ...]]:
        """(time_s, channel, can_id, message, {signal: value}) per exported frame."""
        t0: float | None = None
        for frame in msgs:
            if frame.is_error_frame or frame.is_remote_frame:
                self.skipped["error_frame" if frame.is_error_frame else "remote_frame"] += 1
                continue
            base = frame.arbitration_id - self.offset
            if base not in self.wanted:
                reason = "not selected" if base in self.all_ids else \
                    f"id 0x{frame.arbitration_id:03X} not in the DBC"
                self.skipped[reason] += 1
                continue
            msg = self.by_id[base]
            try:
                values = msg.decode(bytes(frame.data), decode_choices=self.choices)
            except Exception as exc:  # cantools raises several types for a bad frame
                self.skipped[f"{msg.name}: {type(exc).__name__}"] += 1
                continue
            t0 = frame.timestamp if t0 is None else t0
            t = frame.timestamp - t0 if relative else frame.timestamp
            self.exported += 1
            yield (f"{t:.6f}", frame.channel or "", f"0x{frame.arbitration_id:03X}", msg.name,
                   values)

    def write(self, out: IO[str], msgs: Iterable[Any], fmt: str, relative: bool,
              progress: IO[str] | None = None) -> None:
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(WIDE_HEAD + self.columns if fmt == "wide" else LONG_HEAD)
        index = {c: i for i, c in enumerate(self.columns)}
        units = {f"{m.name}.{s.name}": s.unit or "" for m in self.by_id.values()
                 for s in m.signals}
        last = time.monotonic()
        for t, channel, can_id, name, values in self.decoded(msgs, relative):
            if fmt == "wide":
                cells: list[Any] = [""] * len(self.columns)
                for sig, v in values.items():
                    cells[index[f"{name}.{sig}"]] = _value(v)
                writer.writerow([t, channel, can_id, name, *cells])
            else:
                for sig, v in values.items():
                    writer.writerow([t, channel, can_id, name, sig, _value(v),
                                     units[f"{name}.{sig}"]])
            if progress is not None and time.monotonic() - last >= _PROGRESS_S:
                last = time.monotonic()
                print(f"  {self.exported} frames exported ...", file=progress, flush=True)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("can-export", args.log_level)
    try:
        db = load_dbc(args.dbc)
        exporter = Exporter(db, select(db, args.only), args.sensor_id, args.choices)
        msgs = frames(args.log)
        if args.out:
            with open(args.out, "w", newline="", encoding="utf-8") as out:
                exporter.write(out, msgs, args.format, args.relative_time, sys.stderr)
        else:
            exporter.write(sys.stdout, msgs, args.format, args.relative_time)
    except ExportError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        raise               # the reader went away (| head): aeb ends quietly
    except OSError as exc:
        print(f"error: {args.out}: {exc.strerror}", file=sys.stderr)
        return 2
    skipped = ", ".join(f"{n} {reason}" for reason, n in exporter.skipped.most_common())
    print(f"{exporter.exported} frames exported{' to ' + args.out if args.out else ''}"
          f"{'; skipped: ' + skipped if skipped else ''}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
