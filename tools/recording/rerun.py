"""`aeb rerun`: one service's pure core over a recording, offline (process replay).

    aeb rerun fusion drive.mcap --compare                      # same config: no difference
    aeb rerun fusion drive.mcap --compare --set fusion.verifier.params.tau=2.0
    aeb rerun fusion drive.mcap -c my-fusion.toml -o rerun.mcap  # opens beside the original
    aeb rerun fusion drive.mcap --compare --expect declared.json  # CI: only what is declared
    aeb rerun radar drive.mcap -c deploy/radar.toml --compare  # needs the raw CAN recorded

No Zenoh and no clock: the recorded inputs in the recorded order, at the recorded times;
the same recording and configuration give the same output bytes. `--compare` pairs the
re-run's outputs with the recorded ones cycle by cycle and prints a table of what
changed (commands, decisions, densities, tracks); with `--expect FILE` only the
differences declared in FILE are allowed (`--write-expected FILE` writes them).

The outputs go to `-o` as MCAP, under the instance `--out-instance` (default `rerun`),
with their Foxglove views: open it in Foxglove beside the original.

Exit codes: 0 done (and, with --compare, no difference beyond those declared), 1 a
difference not declared (or a declared one that did not happen), 2 bad arguments, config
or recording, or nothing to compare with (the recording holds no output of the instance
compared: the error names the instances it holds).
"""

import argparse
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config
from aeb_radar_camera.common.config.overrides import add_set_argument
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS, RADAR_TRACKS
from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.messages import VerifiedTargets, encode
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.fusion.evidence import (
    APPEARANCE_VETO,
    CANNOT_TELL_KEY,
    EVIDENCE_KEY,
    LLR_KEY,
)
from aeb_radar_camera.tools.recording.compare import (
    Comparison,
    Difference,
    check_declared,
    summary_table,
)
from aeb_radar_camera.tools.recording.format import stack_channel

if TYPE_CHECKING:      # the re-runs' own imports wait for the arguments (`--help`, no extra)
    from aeb_radar_camera.tools.recording.reader import Recording
    from aeb_radar_camera.tools.recording.writer import RecordingWriter


class Progress:
    def __init__(self, total_ns: int, enabled: bool) -> None:
        self.total_ns = max(1, total_ns)
        self.enabled = enabled
        self.t0 = time.monotonic()
        self._next = self.t0 + 2.0

    def __call__(self, done_ns: int, cycles: int) -> None:
        now = time.monotonic()
        if self.enabled and now >= self._next:
            self._next = now + 2.0
            rtf = done_ns / 1e9 / max(1e-9, now - self.t0)
            print(f"  {100 * done_ns / self.total_ns:5.1f}%  {cycles} cycles  "
                  f"{rtf:.1f}x real time", file=sys.stderr, flush=True)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb rerun", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("service", choices=["fusion", "radar"])
    parser.add_argument("recording", nargs="+", help="MCAP file(s) or a folder of them")
    parser.add_argument("-c", "--config", default="",
                        help="the service's config (default: the shipped deploy/fusion.toml "
                             "or deploy/radar.toml)")
    add_set_argument(parser)
    parser.add_argument("--instance", default="",
                        help="fusion: the recorded instance to compare with (default: the "
                             "config's)")
    parser.add_argument("--vehicle", default="", help="default: the recording's")
    parser.add_argument("-o", "--out", default="", help="write the re-run's outputs here")
    parser.add_argument("--out-instance", default="rerun",
                        help="the outputs' instance in the new MCAP (fusion)")
    parser.add_argument("--no-views", action="store_true",
                        help="no Foxglove views in the output file")
    parser.add_argument("--compare", action="store_true",
                        help="compare with the recorded outputs, cycle by cycle")
    parser.add_argument("--exact", action="store_true",
                        help="compare numbers bit for bit (default: to a relative 1e-6)")
    parser.add_argument("--expect", default="", help="differences declared allowed (JSON)")
    parser.add_argument("--write-expected", default="",
                        help="write the differences found as a declaration (JSON)")
    parser.add_argument("--json", default="", help="write the comparison and timing here")
    parser.add_argument("--show", type=int, default=20, help="differences to list")
    parser.add_argument("--start", type=float, default=None, help="seconds from the start")
    parser.add_argument("--end", type=float, default=None, help="seconds from the start")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.add_argument("--evidence", action="store_true",
                        help="fusion: print each cycle's per-track evidence (the verifier's "
                             "per-frame llr and the track's sum), for verifiers that have one")
    add_log_level(parser, "WARNING")
    return parser.parse_args(argv)


def _window(rec: "Recording", args: argparse.Namespace) -> tuple[int, int, int | None, int | None]:
    first, last = rec.time_range()
    start = None if args.start is None else first + round(args.start * 1e9)
    end = None if args.end is None else first + round(args.end * 1e9)
    return first, last, start, end


def run_fusion(args: argparse.Namespace, rec: "Recording",
               vehicle: str) -> tuple[Comparison, dict[str, Any]]:
    from aeb_radar_camera.tools.recording.foxglove_views import Converter, encode_derived
    from aeb_radar_camera.tools.recording.rerun_fusion import FusionRerun, config_params, normalised

    cfg = load_config(args.config or DEPLOY / "fusion.toml", FusionConfig, args.overrides)
    rerun = FusionRerun(cfg, args.instance or None, vehicle)
    first, last, start, end = _window(rec, args)
    span_start = start if start is not None else first
    progress = Progress((end if end is not None else last) - span_start, not args.quiet)
    comparison = Comparison(exact=args.exact)
    writer = _writer(args, {"source": ",".join(map(str, rec.files)), "service": "fusion",
                            "config": json.dumps(config_params(cfg))})
    converter = None if args.no_views else Converter(vehicle, cfg.fusion.decision)
    t0 = time.perf_counter()
    cmd_topic = FUSION_BRAKE_CMD.key(vehicle, instance=args.out_instance)
    tgt_topic = FUSION_TARGETS.key(vehicle, instance=args.out_instance)
    for cycle in rerun.run(rec, start, end):
        assert cycle.result is not None
        result = normalised(cycle.result)
        if args.compare:
            comparison.add(cycle.tracks.header.seq, cycle.tracks.header.stamp_ns,
                           cycle.recorded_cmd, result.command, cycle.recorded, result.targets)
        if writer is not None:
            log_ns = cycle.recorded_log_ns or cycle.log_ns
            stamp = cycle.tracks.header.stamp_ns
            writer.write(cmd_topic, stack_channel(type(result.command)),
                         encode(result.command), log_ns, stamp, result.command.header.seq)
            writer.write(tgt_topic, stack_channel(type(result.targets)),
                         encode(result.targets), log_ns, stamp, result.targets.header.seq)
            if converter is not None:
                views = converter.convert(FUSION_TARGETS.name, msgspec.structs.replace(
                    result.targets, instance=args.out_instance))
                views += converter.convert(FUSION_BRAKE_CMD.name, msgspec.structs.replace(
                    result.command, instance=args.out_instance))
                for topic, view in views:
                    kind, data = encode_derived(view)
                    writer.write(topic, kind, data, log_ns, log_ns)
        if args.evidence:
            for line in evidence_lines(result.targets, span_start):
                print(line)
        progress(cycle.log_ns - span_start, rerun.stats.cycles)
    wall_s = time.perf_counter() - t0
    if writer is not None:
        writer.close()
    st = rerun.stats
    span_s = ((st.last_log_ns or 0) - (st.first_log_ns or 0)) / 1e9
    timing = {"cycles": st.cycles, "recording_s": span_s, "wall_s": wall_s,
              "realtime_factor": span_s / wall_s if wall_s > 0 else None,
              "frames_in_recording": st.frames_in_recording,
              "frames_decoded": st.frames_decoded, "frames_pinned": st.frames_pinned,
              "depth_pinned": st.depth_pinned, "depth_missing": st.depth_missing,
              "frames_undecodable": st.frames_undecodable, "failed_cycles": st.failed_cycles,
              "undecodable": st.undecodable, "instance": rerun.instance,
              "verifier": cfg.fusion.verifier.name,
              "verifier_params": dict(cfg.fusion.verifier.params)}
    print(f"re-ran fusion ({cfg.fusion.verifier.name} {dict(cfg.fusion.verifier.params)}) on "
          f"{st.cycles} radar cycles, {span_s:.1f} s of recording, in {wall_s:.2f} s: "
          f"{timing['realtime_factor'] or 0:.1f}x real time; frames decoded "
          f"{st.frames_decoded} of {st.frames_in_recording}"
          + (f"; {st.failed_cycles} cycles failed" if st.failed_cycles else ""))
    if st.depth_missing:
        print(f"note: {st.depth_missing} frame(s) had their depth in the live instance, but "
              "the recording does not hold it: the cycles checked in them may differ")
    return comparison, timing


def evidence_lines(targets: VerifiedTargets, first_ns: int) -> list[str]:
    """`t=  1.234 s  track 7  18.2 m  llr -1.00  sum -3.00  depth_sees_through  REJECTED
    NONE`: one line per target whose gate_detail holds an accumulated llr."""
    out = []
    for t in targets.targets:
        d = t.gate_detail
        if EVIDENCE_KEY not in d:
            continue
        why = ",".join(k for k, v in d.items()
                       if v and (k.startswith("depth_")
                                 or k in (APPEARANCE_VETO, CANNOT_TELL_KEY)))
        out.append(f"t={(targets.header.stamp_ns - first_ns) / 1e9:8.3f} s  track "
                   f"{t.track_id:<4} {t.range_m:5.1f} m  llr {d.get(LLR_KEY, 0.0):+.2f}  sum "
                   f"{d[EVIDENCE_KEY]:+.2f}  {why or '-'}  {t.verification.value}  "
                   f"{t.decision.value}")
    return out


def run_radar(args: argparse.Namespace, rec: "Recording",
              vehicle: str) -> tuple[Comparison, dict[str, Any]]:
    from aeb_radar_camera.tools.recording.foxglove_views import Converter, encode_derived
    from aeb_radar_camera.tools.recording.rerun_radar import RadarRerun

    cfg = load_config(args.config or DEPLOY / "radar.toml", RadarConfig, args.overrides)
    rerun = RadarRerun(cfg.radar, vehicle, exact=args.exact)
    _, _, start, end = _window(rec, args)
    writer = _writer(args, {"source": ",".join(map(str, rec.files)), "service": "radar"})
    converter = None if args.no_views else Converter(vehicle)
    t0 = time.perf_counter()
    comparison = rerun.comparison
    for recorded, tracks, log_ns in rerun.run(rec, start, end, compare=args.compare):
        if writer is not None:
            topic = RADAR_TRACKS.key(vehicle, sensor=tracks.sensor).replace(
                f"/radar/{tracks.sensor}/", f"/radar/{args.out_instance}-{tracks.sensor}/")
            writer.write(topic, stack_channel(type(tracks)), encode(tracks), log_ns,
                         tracks.header.stamp_ns, tracks.header.seq)
            if converter is not None:
                renamed = msgspec.structs.replace(
                    tracks, sensor=f"{args.out_instance}-{tracks.sensor}")
                for view_topic, view in converter.convert(RADAR_TRACKS.name, renamed):
                    kind, data = encode_derived(view)
                    writer.write(view_topic, kind, data, log_ns, log_ns)
        del recorded
    wall_s = time.perf_counter() - t0
    if writer is not None:
        writer.close()
    span_s = rerun.span_s
    timing = {"cycles": rerun.cycles, "frames": rerun.frames, "recording_s": span_s,
              "wall_s": wall_s, "realtime_factor": span_s / wall_s if wall_s > 0 else None}
    if rerun.frames == 0:
        print(f"error: the recording has no raw CAN frames ({rerun.can_topic}); record "
              "them with [radar.raw_can] publish = true or `aeb record --can`",
              file=sys.stderr)
        raise SystemExit(2)
    print(f"re-ran radar on {rerun.frames} CAN frames, {rerun.cycles} cycles, {span_s:.1f} s "
          f"of recording, in {wall_s:.2f} s: {timing['realtime_factor'] or 0:.1f}x real time")
    return comparison, timing


def _writer(args: argparse.Namespace, metadata: dict[str, str]) -> "RecordingWriter | None":
    from aeb_radar_camera.tools.recording.writer import RecordingWriter

    if not args.out:
        return None
    # No time-based flush: the same outputs must make the same bytes.
    return RecordingWriter(args.out, metadata=metadata, flush_s=None)


def report(args: argparse.Namespace, comparison: Comparison, timing: dict[str, Any]) -> int:
    code = 0
    result: dict[str, Any] = {"timing": timing}
    if args.compare:
        print(summary_table(comparison))
        for d in comparison.differences[:args.show]:
            print("  " + d.text())
        if len(comparison.differences) > args.show:
            print(f"  ... {len(comparison.differences) - args.show} more")
        declared: list[Difference] = []
        if args.expect:
            try:
                data = json.loads(Path(args.expect).read_text())
                declared = [Difference.from_json(d) for d in data["differences"]]
            except (OSError, ValueError, KeyError, TypeError) as exc:
                print(f"error: {args.expect}: not a declaration of differences ({exc})",
                      file=sys.stderr)
                return 2
        undeclared, missing = check_declared(comparison.differences, declared)
        if undeclared or missing:
            code = 1
            print(f"{len(undeclared)} difference(s) not declared, {len(missing)} declared "
                  "difference(s) that did not happen" if args.expect else
                  f"{len(undeclared)} difference(s)")
            for d in missing[:args.show]:
                print("  declared, not found: " + d.text())
        elif comparison.cycles:
            print("no difference" + (" beyond those declared" if declared else ""))
        result["comparison"] = {"cycles": comparison.cycles,
                                "cycles_differing": comparison.cycles_differing,
                                "compared": dict(comparison.compared),
                                "differing": dict(comparison.differing),
                                "fields": dict(comparison.fields),
                                "undeclared": len(undeclared), "missing": len(missing)}
        if args.write_expected:
            Path(args.write_expected).write_text(json.dumps(
                {"recording": " ".join(args.recording),
                 "set": [o.assignment for o in args.overrides],
                 "config": args.config,
                 "differences": [d.as_json() for d in comparison.differences]}, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return code


def nothing_compared(args: argparse.Namespace, rec: "Recording", vehicle: str,
                     timing: dict[str, Any]) -> str:
    """Why --compare found no recorded output to compare with, naming what is there."""
    spec = FUSION_BRAKE_CMD if args.service == "fusion" else RADAR_TRACKS
    param = "instance" if args.service == "fusion" else "sensor"
    found = sorted({m[param] for topic in rec.channels()
                    if (m := spec.match(topic, vehicle)) is not None})
    what = (f"fusion instance {timing.get('instance')!r}" if args.service == "fusion"
            else "the configured radar sensors")
    there = (f"it holds {param} {', '.join(map(repr, found))}" if found
             else f"it holds no {spec.name} of vehicle {vehicle!r} at all")
    hint = (f" (--instance {found[0]} compares with it)" if args.service == "fusion"
            and len(found) == 1 else "")
    return (f"nothing compared: the recording holds no output of {what} in the "
            f"{timing.get('cycles', 0)} radar cycles re-run; {there}{hint}")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from aeb_radar_camera.services.fusion.verifiers import VerifierConfigError
    from aeb_radar_camera.tools.recording.reader import Recording, RecordingError

    setup_logging("rerun", args.log_level)
    try:
        rec = Recording.open(args.recording)
        vehicle = args.vehicle or rec.metadata().get("vehicle", "ego")
        run = run_fusion if args.service == "fusion" else run_radar
        comparison, timing = run(args, rec, vehicle)
    except (RecordingError, ConfigError, VerifierConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    code = report(args, comparison, timing)
    if args.compare and comparison.cycles == 0:
        print(f"error: {nothing_compared(args, rec, vehicle, timing)}", file=sys.stderr)
        return 2
    return code


if __name__ == "__main__":
    sys.exit(main())
