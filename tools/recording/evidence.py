"""`aeb evidence`: a self-contained folder for every WARNING and BRAKE, written by a
recorder process (never by fusion, whose cycle stays as it is).

    aeb evidence --out evidence/                          # live, beside the stack
    aeb evidence --from drive.mcap --out evidence/        # from a recording
    aeb record -o drive.mcap --evidence evidence/         # both, in one process

An event starts when a fusion instance's command rises to WARNING or BRAKE (from a lower
decision, or for another track); held BRAKE cycles belong to the event that braked. Its
folder, `<UTC time>_<instance>_<DECISION>_radar<seq>_track<id>/`, holds:

- README.md: why, in words: the deciding track's range, range rate, TTC and TTC_eff
  against the thresholds, the verifier's score against its threshold, the corridor
  check, and the stage timestamps from the radar's last CAN frame to the brake;
- event.json: the same, for tools; command.json, targets.json, tracks.json (the cycle);
- history.json and history.png: the deciding track over the seconds before (the plot
  when matplotlib is installed);
- frame.jpg (as recorded), frame_annotated.jpg (every ROI of the cycle), roi.png (the
  deciding ROI), roi_edges.png (the Canny edges the edge-density gate counts at the
  verifier's thresholds, for the edge-density verifiers);
- can.log (candump format): the cycle's raw CAN frames, when they were recorded;
- brake_status.json: the brake's statuses from the command on.

Exit codes: 0, 2 for bad arguments, a recording that cannot be read, or no bus.
"""

import argparse
import json
import math
import sys
import threading
from collections import deque
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import msgspec

from aeb_radar_camera.common.config.fusion import DecisionSettings
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_JPEG,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_CAN,
    RADAR_TRACKS,
)
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeStatus,
    CompressedFrame,
    Decision,
    RadarTracks,
    RawCanFrames,
    VerifiedTarget,
    VerifiedTargets,
)
from aeb_radar_camera.common.messages.radar import can_message
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, open_bus, run_until

# What draws, decodes and writes CAN logs is imported where it is used: `aeb evidence
# --help` needs no extra installed.

HISTORY_S = 3.0
# An event is written once the stream is this far past its cycle: its targets, raw CAN
# batch and the brake's answer have arrived by then.
SETTLE_NS = 500_000_000
FRAMES_KEPT = 90


@dataclass
class Event:
    instance: str
    command: BrakeCommand
    log_ns: int
    tracks: RadarTracks | None
    targets: VerifiedTargets | None = None
    targets_log_ns: int | None = None
    statuses: list[BrakeStatus] = field(default_factory=list)


def _json(obj: Any) -> str:
    return json.dumps(msgspec.to_builtins(obj), indent=1)


class EvidenceCollector:
    """Fed every decoded stack message (`on_message`), in receive order; writes an
    evidence folder under `out` per event. `decision`: the thresholds and corridor the
    README cites (the fusion config's, or the defaults)."""

    def __init__(self, out: Path, vehicle: str, decision: DecisionSettings | None = None,
                 history_s: float = HISTORY_S) -> None:
        self.out = out
        self.vehicle = vehicle
        self.decision = decision or DecisionSettings()
        self.history_ns = round(history_s * 1e9)
        self.written: list[Path] = []
        self._tracks: dict[str, deque[tuple[int, RadarTracks]]] = {}
        self._targets: dict[str, deque[tuple[int, VerifiedTargets]]] = {}
        self._frames: dict[str, deque[tuple[int, bytes, CompressedFrame]]] = {}
        self._can: deque[tuple[int, RawCanFrames]] = deque()
        self._last: dict[str, tuple[Decision, int]] = {}
        self._pending: list[Event] = []
        self._lock = threading.Lock()
        from aeb_radar_camera.tools.recording.foxglove_views import DECISION_LEVEL

        self._level = DECISION_LEVEL

    def on_message(self, spec_name: str, key: str, msg: Any, payload: bytes,
                   log_ns: int) -> None:
        with self._lock:
            self._take(spec_name, msg, payload, log_ns)
            ready = [e for e in self._pending if log_ns - e.log_ns >= SETTLE_NS]
            for event in ready:
                self._pending.remove(event)
                self._write(event)

    def close(self) -> None:
        with self._lock:
            for event in self._pending:
                self._write(event)
            self._pending.clear()

    def _take(self, spec_name: str, msg: Any, payload: bytes, log_ns: int) -> None:
        edge = log_ns - self.history_ns
        if spec_name == RADAR_TRACKS.name:
            _keep(self._tracks.setdefault(msg.sensor, deque()), (log_ns, msg), edge)
        elif spec_name == CAMERA_JPEG.name:
            frames = self._frames.setdefault(msg.camera, deque(maxlen=FRAMES_KEPT))
            frames.append((log_ns, payload, msg))
        elif spec_name == RADAR_CAN.name:
            _keep(self._can, (log_ns, msg), edge)
        elif spec_name == FUSION_TARGETS.name:
            _keep(self._targets.setdefault(msg.instance, deque()), (log_ns, msg), edge)
            for e in self._pending:
                if e.targets is None and e.instance == msg.instance and \
                        e.command.radar_seq == msg.radar_seq and \
                        e.command.header.stamp_ns == msg.header.stamp_ns:
                    e.targets, e.targets_log_ns = msg, log_ns
        elif spec_name == BRAKE_STATUS.name:
            for e in self._pending:
                if e.instance == msg.instance:
                    e.statuses.append(msg)
        elif spec_name == FUSION_BRAKE_CMD.name:
            self._on_command(msg, log_ns)

    def _on_command(self, cmd: BrakeCommand, log_ns: int) -> None:
        prev, prev_track = self._last.get(cmd.instance, (Decision.NONE, -1))
        self._last[cmd.instance] = (cmd.decision, cmd.track_id)
        level = self._level[cmd.decision]
        if level == 0 or cmd.held:
            return
        if level > self._level[prev] or cmd.track_id != prev_track:
            self._pending.append(Event(cmd.instance, cmd, log_ns, self._cycle_tracks(cmd)))

    def _cycle_tracks(self, cmd: BrakeCommand) -> RadarTracks | None:
        """The radar cycle a command answered (same sequence number and stamp)."""
        for history in self._tracks.values():
            for _, t in reversed(history):
                if t.header.seq == cmd.radar_seq and t.header.stamp_ns == cmd.header.stamp_ns:
                    return t
        return None

    # -- writing ------------------------------------------------------------------------

    def _write(self, e: Event) -> None:
        cmd = e.command
        when = datetime.fromtimestamp(cmd.header.stamp_ns / 1e9, UTC)
        name = (f"{when:%Y%m%dT%H%M%S}.{when.microsecond // 1000:03d}Z_{e.instance}_"
                f"{cmd.decision.value}_radar{cmd.radar_seq}_track{cmd.track_id}")
        folder = self.out / name
        folder.mkdir(parents=True, exist_ok=True)
        target = None
        if e.targets is not None:
            target = next((t for t in e.targets.targets if t.track_id == cmd.track_id), None)
        (folder / "command.json").write_text(_json(cmd))
        if e.targets is not None:
            (folder / "targets.json").write_text(_json(e.targets))
        if e.tracks is not None:
            (folder / "tracks.json").write_text(_json(e.tracks))
        (folder / "brake_status.json").write_text(_json(e.statuses))
        history = self._history(e, cmd.track_id)
        (folder / "history.json").write_text(json.dumps(history, indent=1))
        self._plot_history(history, folder / "history.png", cmd)
        files = self._images(e, target, folder)
        can_frames = self._can_frames(e, folder)
        summary = self._summary(e, target, can_frames, files)
        (folder / "event.json").write_text(json.dumps(summary, indent=1))
        (folder / "README.md").write_text(_readme(summary))
        self.written.append(folder)

    def _history(self, e: Event, track_id: int) -> list[dict[str, Any]]:
        """The deciding track in every recent radar cycle, with fusion's view of it."""
        fused = {t.radar_seq: t for _, t in self._targets.get(e.instance, ())}
        out: list[dict[str, Any]] = []
        if e.tracks is None:
            return out
        for _, tracks in self._tracks.get(e.tracks.sensor, ()):
            if tracks.header.stamp_ns > e.command.header.stamp_ns:
                break
            t = next((t for t in tracks.tracks if t.track_id == track_id), None)
            if t is None:
                continue
            row: dict[str, Any] = {
                "radar_seq": tracks.header.seq,
                "t_s": (tracks.header.stamp_ns - e.command.header.stamp_ns) / 1e9,
                **{k: getattr(t, k) for k in ("x_m", "y_m", "vx_mps", "vy_mps", "range_m",
                                              "range_rate_mps", "rcs_dbsm", "confirmed")}}
            vt = fused.get(tracks.header.seq)
            ft = next((x for x in vt.targets if x.track_id == track_id), None) if vt else None
            if ft is not None:
                row.update(ttc_s=ft.ttc_s, ttc_eff_s=ft.ttc_eff_s, density=ft.density,
                           verification=ft.verification.value, decision=ft.decision.value,
                           in_path=ft.in_path)
            out.append(row)
        return out

    def _plot_history(self, history: list[dict[str, Any]], path: Path,
                      cmd: BrakeCommand) -> None:
        if not history:
            return
        try:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ImportError:     # an install without the plots (no demo extra): JSON only
            return

        t = [h["t_s"] for h in history]
        fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
        ax1.plot(t, [h["range_m"] for h in history], "o-", label="range (m)")
        ax1.set_ylabel("range (m)")
        ax1.set_title(f"track {cmd.track_id} before {cmd.decision.value} "
                      f"(radar #{cmd.radar_seq})")
        ttc = [(h["t_s"], h.get("ttc_eff_s")) for h in history if h.get("ttc_eff_s") is not None]
        if ttc:
            ax2.plot([a for a, _ in ttc], [b for _, b in ttc], "o-", label="TTC_eff (s)")
        ax2.axhline(self.decision.brake_ttc_eff_s, color="r", ls="--", label="BRAKE below")
        ax2.axhline(self.decision.warning_ttc_eff_s, color="orange", ls="--",
                    label="WARNING below")
        ax2.set_ylabel("TTC_eff (s)")
        ax2.set_xlabel("time before the decision (s)")
        ax2.legend(loc="best", fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=80)
        plt.close(fig)

    def _images(self, e: Event, target: VerifiedTarget | None, folder: Path) -> list[str]:
        if e.targets is None or target is None or target.frame_seq is None:
            return []
        camera = target.camera or (e.targets.camera.split(",")[0] if e.targets.camera else "")
        found = next(((p, f) for _, p, f in self._frames.get(camera, ())
                      if f.header.seq == target.frame_seq), None)
        if found is None:
            return []
        _, frame = found
        (folder / "frame.jpg").write_bytes(frame.jpeg)
        from aeb_radar_camera.common.imaging import ImageDecodeError, decode_bgr
        from aeb_radar_camera.tools.recording.evidence_frames import write_images

        try:
            bgr = decode_bgr(frame.jpeg, frame.crc32)
        except ImageDecodeError:
            return ["frame.jpg"]
        return ["frame.jpg", *write_images(folder, bgr, e.targets, target, camera)]

    def _can_frames(self, e: Event, folder: Path) -> int:
        """The frames of the cycle: after the previous cycle's last frame, up to this
        cycle's (same host monotonic clock as the radar)."""
        if e.tracks is None or not self._can:
            return 0
        end = e.tracks.last_frame_mono_ns
        prev = next((t.last_frame_mono_ns for _, t in reversed(self._tracks.get(
            e.tracks.sensor, ())) if t.header.seq < e.tracks.header.seq), end - 200_000_000)
        frames = [(batch, f) for _, batch in self._can for f in batch.frames
                  if prev < f.rx_mono_ns <= end]
        if not frames:
            return 0
        import can

        writer = can.CanutilsLogWriter(str(folder / "can.log"), channel=frames[0][0].bus)
        try:
            for _, f in frames:
                writer.on_message_received(can_message(f, f.rx_wall_ns / 1e9))
        finally:
            writer.stop()
        return len(frames)

    def _summary(self, e: Event, t: VerifiedTarget | None, can_frames: int,
                 images: list[str]) -> dict[str, Any]:
        cmd, d = e.command, self.decision
        c = d.corridor
        near_m, far_m = d.range_bounds_m
        out: dict[str, Any] = {
            "vehicle": self.vehicle, "instance": e.instance, "decision": cmd.decision.value,
            "brake_level_pct": cmd.brake_level_pct, "radar_seq": cmd.radar_seq,
            "radar_stamp_ns": cmd.header.stamp_ns,
            "radar_stamp_utc": datetime.fromtimestamp(cmd.header.stamp_ns / 1e9, UTC)
            .isoformat(), "reason": cmd.reason, "track_id": cmd.track_id,
            "verifier_status": cmd.verifier_status.value, "images": images,
            "can_frames": can_frames,
            "thresholds": {"brake_ttc_eff_s": d.brake_ttc_eff_s,
                           "warning_ttc_eff_s": d.warning_ttc_eff_s,
                           "ttc_offset_s": d.ttc_offset_s, "min_range_m": near_m,
                           "max_range_m": far_m},
        }
        if e.targets is not None:
            out["verifier"] = {"name": e.targets.verifier, "params": e.targets.verifier_params}
        if t is not None:
            tau = (e.targets.verifier_params.get("tau") if e.targets is not None else None)
            out["track"] = {
                "range_m": t.range_m, "range_rate_mps": t.range_rate_mps, "x_m": t.x_m,
                "y_m": t.y_m, "ttc_s": t.ttc_s, "ttc_eff_s": t.ttc_eff_s,
                "verification": t.verification.value, "density": t.density,
                "threshold": tau, "gate_detail": t.gate_detail, "roi_xywh": list(t.roi_xywh),
                "frame_seq": t.frame_seq, "frame_age_ms": t.frame_age_ms,
                "camera": t.camera, "reason": t.reason}
            out["corridor"] = {
                "enabled": c.enabled, "center_y_m": c.center_y_m,
                "half_width_m": c.half_width_m, "margin_m": c.margin_m,
                "lateral_offset_m": t.y_m - c.center_y_m, "in_path": t.in_path,
                "path_predicted": t.path_predicted}
        if e.targets is not None and (e.targets.path or cmd.override):
            # The kinematic rule: the vehicle's state it used and the driver's override.
            k = d.kinematic
            out["vehicle_state"] = {
                "ego_speed_mps": e.targets.ego_speed_mps,
                "ego_yaw_rate_dps": e.targets.ego_yaw_rate_dps, "path": e.targets.path,
                "degraded": e.targets.vehicle_state, "override": cmd.override}
            if t is not None:
                out["kinematic"] = {
                    "required_decel_mps2": t.required_decel_mps2, "accel_mps2": t.accel_mps2,
                    "path_s_m": t.path_s_m, "path_d_m": t.path_d_m,
                    "brake_level_pct": t.brake_level_pct,
                    "bounds": {"warning": [k.warning_decel_mps2, k.warning_ttc_s],
                               "partial": [k.partial_decel_mps2, k.partial_ttc_s],
                               "full": [k.full_decel_mps2, k.full_ttc_s]}}
        out["stages"] = self._stages(e)
        return out

    def _stages(self, e: Event) -> list[dict[str, Any]]:
        """Each stage's time: monotonic ones relative to the radar cycle's last CAN frame
        (the same host's clock), wall-clock ones relative to the radar stamp."""
        rows: list[dict[str, Any]] = []
        cmd = e.command
        base = cmd.radar_last_frame_mono_ns

        def mono(stage: str, ns: int | None) -> None:
            if ns:
                rows.append({"stage": stage, "clock": "monotonic", "ms": (ns - base) / 1e6})

        def wall(stage: str, ns: int | None) -> None:
            if ns:
                rows.append({"stage": stage, "clock": "wall",
                             "ms": (ns - cmd.header.stamp_ns) / 1e6})

        mono("radar: last CAN frame of the cycle", base)
        if e.tracks is not None:
            rows.append({"stage": "radar: decode and track", "clock": "duration",
                         "ms": e.tracks.processing_ns / 1e6})
            mono("radar: tracks published", e.tracks.header.pub_mono_ns)
        mono("fusion: command published", cmd.header.pub_mono_ns)
        if e.targets is not None:
            rows.append({"stage": "fusion: tracks received -> decided", "clock": "duration",
                         "ms": e.targets.processing_ns / 1e6})
            mono("fusion: targets published", e.targets.header.pub_mono_ns)
            for t in e.targets.targets:
                if t.track_id == cmd.track_id and t.frame_age_ms is not None:
                    wall("camera: frame captured", cmd.header.stamp_ns
                         - round(t.frame_age_ms * 1e6))
        status = next((s for s in e.statuses if s.last_cmd_seq == cmd.header.seq), None)
        if status is not None:
            if status.radar_to_serial_us is not None:
                rows.append({"stage": "brake: command bytes on the serial line",
                             "clock": "monotonic", "ms": status.radar_to_serial_us / 1e3})
            if status.cmd_to_serial_us is not None:
                rows.append({"stage": "brake: command received -> serial", "clock": "duration",
                             "ms": status.cmd_to_serial_us / 1e3})
            rows.append({"stage": f"brake: state {status.state.value}", "clock": "",
                         "ms": None})
        wall("recorder: command received", e.log_ns)
        return rows


def _keep(q: deque[Any], item: tuple[int, Any], edge: int) -> None:
    q.append(item)
    while q and q[0][0] < edge:
        q.popleft()


def _fmt(v: Any, unit: str = "", digits: int = 2) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}f}{unit}" if math.isfinite(v) else str(v)
    return f"{v}{unit}"


def _readme(s: dict[str, Any]) -> str:
    lines = [f"# {s['decision']} by fusion instance `{s['instance']}`, radar cycle "
             f"#{s['radar_seq']}", "", f"{s['radar_stamp_utc']} (vehicle {s['vehicle']})", "",
             f"**Why:** {s['reason']}", ""]
    t, c, th = s.get("track"), s.get("corridor"), s["thresholds"]
    if t is not None and c is not None:
        lines += [
            f"## Track {s['track_id']}", "",
            "| check | value | rule |", "|---|---|---|",
            f"| range | {_fmt(t['range_m'], ' m', 1)} | {th['min_range_m']} to "
            f"{th['max_range_m']} m |",
            f"| range rate | {_fmt(t['range_rate_mps'], ' m/s', 2)} | closing < 0 |",
            f"| TTC | {_fmt(t['ttc_s'], ' s')} | |",
            f"| TTC_eff = TTC - {th['ttc_offset_s']} s | {_fmt(t['ttc_eff_s'], ' s')} | "
            f"BRAKE < {th['brake_ttc_eff_s']} s, WARNING < {th['warning_ttc_eff_s']} s |",
            f"| {s.get('verifier', {}).get('name', '?')} score | "
            f"{_fmt(t['density'], '', 4)} | verified >= {_fmt(t['threshold'], '', 4)} |",
            f"| verification | {t['verification']} | |",
            f"| lateral offset | {_fmt(c['lateral_offset_m'], ' m')} | in the corridor: "
            f"abs(y) <= {c['half_width_m'] + c['margin_m']:.2f} m (half width + margin); "
            f"{'predicted path' if c['path_predicted'] else 'position'} |",
            f"| in path | {c['in_path']} | corridor check "
            f"{'on' if c['enabled'] else 'off'} |",
            f"| frame | seq {t['frame_seq']}, {_fmt(t['frame_age_ms'], ' ms', 1)} before the "
            f"radar cycle | |", ""]
    v, k = s.get("vehicle_state"), s.get("kinematic")
    if v is not None:
        lines += [
            "## Vehicle state (kinematic rule)", "", "| what | value |", "|---|---|",
            f"| ego speed | {_fmt(v['ego_speed_mps'], ' m/s')} |",
            f"| yaw rate | {_fmt(v['ego_yaw_rate_dps'], ' deg/s')} |",
            f"| path | {v['path'] or '-'} |",
            f"| state | {v['degraded'] or 'fresh'} |",
            f"| driver override | {v['override'] or 'none'} |", ""]
    if k is not None:
        b = k["bounds"]
        lines += [
            "| kinematic check | value | stages (m/s^2, or TTC below s) |", "|---|---|---|",
            f"| required deceleration | {_fmt(k['required_decel_mps2'], ' m/s^2')} | "
            f"warning {b['warning'][0]} / {b['warning'][1]} s, partial {b['partial'][0]} / "
            f"{b['partial'][1]} s, full {b['full'][0]} / {b['full'][1]} s |",
            f"| target acceleration | {_fmt(k['accel_mps2'], ' m/s^2')} | over ground, "
            "along the path |",
            f"| on the path | s {_fmt(k['path_s_m'], ' m', 1)}, offset "
            f"{_fmt(k['path_d_m'], ' m')} | |",
            f"| stage level | {_fmt(k['brake_level_pct'], ' %', 0)} | |", ""]
    lines += ["## Stages", "", "| stage | clock | ms |", "|---|---|---|"]
    lines += [f"| {r['stage']} | {r['clock']} | {_fmt(r['ms'])} |" for r in s["stages"]]
    lines += ["", "Monotonic times are from the radar cycle's last CAN frame (valid when the "
              "services share a host); wall times from the radar stamp.", "",
              "## Files", "", "event.json, command.json, targets.json, tracks.json, "
              "history.json" + ", history.png" + "".join(f", {f}" for f in s["images"])
              + (f", can.log ({s['can_frames']} frames)" if s["can_frames"] else
                 " (no raw CAN recorded)") + ", brake_status.json", ""]
    return "\n".join(lines)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb evidence", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="evidence", help="folders go here")
    parser.add_argument("--from", dest="source", nargs="+", default=None,
                        help="a recording instead of the live bus")
    add_bus_args(parser, connect_timeout_s=0.0)
    parser.add_argument("--fusion-config", default="",
                        help="the thresholds and corridor the README cites")
    parser.add_argument("--duration", type=float, default=None)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from aeb_radar_camera.common.config.loader import ConfigError
    from aeb_radar_camera.tools.recording.reader import Recording, RecordingError, decode_record
    from aeb_radar_camera.tools.recording.recorder import Recorder, decision_settings, selection

    setup_logging("evidence", args.log_level)
    try:
        decision = decision_settings(args.fusion_config)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    if args.source:
        try:
            rec = Recording.open(args.source)
            collector = EvidenceCollector(out, rec.metadata().get("vehicle", args.vehicle),
                                          decision)
            for r in rec.records():
                try:
                    decoded = decode_record(r)
                except ValueError:
                    continue
                if decoded is not None:
                    info, msg = decoded
                    collector.on_message(info.spec.name, r.topic, msg, r.data, r.log_time_ns)
        except RecordingError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        collector.close()
    else:
        stop = stop_event_on_signals()
        collector = EvidenceCollector(out, args.vehicle, decision)
        bus = open_bus(args, "evidence", stop)
        with bus:
            recorder = Recorder(bus, None, selection("", args.vehicle), None, (collector,))
            recorder.start()
            print(f"writing evidence of every WARNING and BRAKE under {out} (Ctrl-C to stop)",
                  file=sys.stderr, flush=True)
            run_until(stop, args.duration)
            recorder.stop()
    for folder in collector.written:
        print(folder)
    print(f"{len(collector.written)} evidence folder(s) under {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
