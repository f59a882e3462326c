"""`aeb calib-check`: draw projected radar tracks over a camera frame, so that a person can
see whether a calibration is right.

    aeb calib-check --calibration deploy/calibration/d435_848x480.toml \\
        --image frame.jpg --track 8,0.8 --track 15,-1 --out check.png
    aeb calib-check --calibration cal.toml --image frame.jpg --tracks cycle.msgpack \\
        --fusion-config deploy/fusion.toml --out check.png

Each track is drawn as fusion sees it: the 0-2.2 m column at the track (blue), and the
ROI from fusion's own code (services/fusion/roi.py) coloured by the verdict of the
configured verifier on the frame decoded by the project's one decode path: green
verified, red rejected. A ground grid (every 5 m, with the in-path corridor) shows
whether the ground plane lines up. A table of ROIs and densities goes to stdout.

Images that are not JPEG (PNG, ...) are JPEG-encoded first at --jpeg-quality, as the
camera service would publish them, so that densities match what fusion computes.

Exit codes: 0 done, 2 bad arguments, calibration, configuration, image or tracks file.
"""

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import msgspec
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.fusion import FusionConfig, FusionSettings
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.imaging import ImageDecodeError, decode_bgr, decode_gray, encode_jpeg
from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.messages import DecodeError, RadarTracks, decode
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from aeb_radar_camera.services.fusion.verifiers import (
    GateResult,
    Observation,
    VerifierConfigError,
    create,
)

_GREEN, _RED, _BLUE, _GREY, _YELLOW = (0, 200, 0), (0, 0, 230), (255, 120, 0), (160, 160, 160), \
    (0, 220, 255)


class CheckError(ValueError):
    """Bad input for calib-check; the message says which."""


@dataclass(frozen=True)
class TrackIn:
    track_id: int
    x_m: float
    y_m: float
    confirmed: bool = True


@dataclass(frozen=True)
class TrackOut:
    track: TrackIn
    roi: Roi | None
    result: GateResult | None


def parse_track(text: str, track_id: int) -> TrackIn:
    """"X,Y" (metres, radar frame: x forward, y left). Raises CheckError."""
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError as exc:
        raise CheckError(f"--track {text!r}: expected X,Y in metres") from exc
    return TrackIn(track_id, x, y)


def load_tracks(path: Path) -> list[TrackIn]:
    """A recorded RadarTracks, msgpack (as on the bus) or JSON. Raises CheckError."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CheckError(f"{path}: cannot read: {exc.strerror}") from exc
    try:
        cycle = decode(data, RadarTracks)
    except DecodeError:
        try:
            cycle = msgspec.json.decode(data, type=RadarTracks)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise CheckError(f"{path}: neither a msgpack nor a JSON RadarTracks: {exc}") from exc
    return [TrackIn(t.track_id, t.x_m, t.y_m, t.confirmed) for t in cycle.tracks]


def load_frame(path: Path, cal: Calibration, quality: int) -> tuple[np.ndarray, np.ndarray, str]:
    """(gray for the gate, BGR for drawing, a note). Raises CheckError."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CheckError(f"{path}: cannot read: {exc.strerror}") from exc
    note = ""
    if not data.startswith(b"\xff\xd8"):
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise CheckError(f"{path}: not an image OpenCV can read")
        data = encode_jpeg(image, quality)
        note = f"not a JPEG: encoded at quality {quality} as the camera would"
    try:
        gray = decode_gray(data, cal.width, cal.height)
        bgr = np.ascontiguousarray(decode_bgr(data))
    except ImageDecodeError as exc:
        raise CheckError(f"{path}: {exc} (calibration {cal.width}x{cal.height})") from exc
    return gray, bgr, note


def check(gray: np.ndarray, tracks: list[TrackIn], projector: ColumnProjector,
          settings: FusionSettings) -> list[TrackOut]:
    verifier = create(settings.verifier.name, settings.verifier.params)
    boxes = projector.boxes(np.array([(t.x_m, t.y_m) for t in tracks]).reshape(-1, 2))
    out = []
    for t, box in zip(tracks, boxes, strict=True):
        if box is None:
            out.append(TrackOut(t, None, None))
        else:
            obs = Observation(gray, *box, math.hypot(t.x_m, t.y_m))
            out.append(TrackOut(t, box[0], verifier.verify(obs)))
    return out


def _polyline(img: np.ndarray, cal: Calibration, pts: np.ndarray, colour: tuple[int, int, int],
              thickness: int = 1) -> None:
    uv, ok = cal.project(pts)
    run: list[list[int]] = []
    for (u, v), good in zip(uv, ok, strict=True):
        if good and abs(u) < 1e5 and abs(v) < 1e5:
            run.append([round(u), round(v)])
        elif run:
            cv2.polylines(img, [np.array(run, np.int32)], False, colour, thickness, cv2.LINE_AA)
            run = []
    if len(run) > 1:
        cv2.polylines(img, [np.array(run, np.int32)], False, colour, thickness, cv2.LINE_AA)


def draw_grid(img: np.ndarray, cal: Calibration, settings: FusionSettings) -> None:
    """Range lines every 5 m (to 25 m) and the corridor's edges, on the ground."""
    ys = np.linspace(-6.0, 6.0, 49)
    for x in range(5, 30, 5):
        _polyline(img, cal, np.stack([np.full_like(ys, x), ys, np.zeros_like(ys)], 1), _GREY)
        uv, ok = cal.project(np.array([[x, 3.5, 0.0]]))
        if ok[0]:
            cv2.putText(img, f"{x} m", (round(uv[0, 0]) + 3, round(uv[0, 1]) - 3),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.4, _GREY, 1, cv2.LINE_AA)
    c = settings.decision.corridor
    xs = np.linspace(1.0, 30.0, 59)
    for side in (-1.0, 1.0):
        y = c.center_y_m + side * (c.half_width_m + c.margin_m)
        _polyline(img, cal, np.stack([xs, np.full_like(xs, y), np.zeros_like(xs)], 1), _YELLOW)


def draw_tracks(img: np.ndarray, projector: ColumnProjector, outs: list[TrackOut]) -> None:
    if not outs:
        return
    uv, valid = projector.project_columns(np.array([(o.track.x_m, o.track.y_m) for o in outs]))
    for o, col, ok in zip(outs, uv, valid, strict=True):
        pts = col[ok]
        if len(pts) > 1:
            cv2.polylines(img, [np.rint(pts).astype(np.int32)], False, _BLUE, 2, cv2.LINE_AA)
        if o.roi is None:
            continue
        colour = _GREEN if o.result is not None and o.result.verified else _RED
        r = o.roi
        cv2.rectangle(img, (r.x, r.y), (r.x + r.w - 1, r.y + r.h - 1), colour, 1)
        label = f"#{o.track.track_id} {o.track.x_m:.1f},{o.track.y_m:.1f}"
        if o.result is not None:
            label += f" d={o.result.score:.3f}"
        if not o.track.confirmed:
            label += " (unconfirmed)"
        cv2.putText(img, label, (r.x, max(10, r.y - 4)), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    colour, 1, cv2.LINE_AA)


def table(outs: list[TrackOut], frame_pixels: int) -> str:
    lines = ["track  x_m     y_m     roi (x,y,w,h)         area%   density  verdict"]
    for o in outs:
        t = o.track
        if o.roi is None:
            lines.append(f"{t.track_id:<6} {t.x_m:<7.2f} {t.y_m:<7.2f} not visible")
            continue
        r, res = o.roi, o.result
        assert res is not None
        verdict = "verified" if res.verified else "rejected"
        if not t.confirmed:
            verdict += " (unconfirmed: fusion skips it)"
        lines.append(f"{t.track_id:<6} {t.x_m:<7.2f} {t.y_m:<7.2f} "
                     f"{f'{r.x},{r.y},{r.w},{r.h}':<21} {100 * r.area / frame_pixels:<7.2f} "
                     f"{res.score:<8.4f} {verdict}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb calib-check", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--calibration", required=True, help="calibration TOML")
    parser.add_argument("--image", required=True, help="a frame from the camera (JPEG, PNG...)")
    parser.add_argument("--out", required=True, help="PNG to write")
    parser.add_argument("--track", action="append", default=[], metavar="X,Y",
                        help="a track position in metres, radar frame (repeatable)")
    parser.add_argument("--tracks", help="a recorded RadarTracks (msgpack or JSON)")
    parser.add_argument("--fusion-config", help="fusion TOML: ROI geometry, verifier, corridor")
    parser.add_argument("--no-grid", action="store_true", help="do not draw the ground grid")
    parser.add_argument("--jpeg-quality", type=int, default=80,
                        help="quality for non-JPEG images (the camera's, default 80)")
    add_log_level(parser, "WARNING")
    args = parser.parse_args(argv)
    setup_logging("calib-check", args.log_level)
    try:
        cal = Calibration.load(args.calibration)
        settings = (load_config(args.fusion_config, FusionConfig).fusion if args.fusion_config
                    else parse_config({}, FusionConfig).fusion)
        tracks = [parse_track(t, i + 1) for i, t in enumerate(args.track)]
        if args.tracks:
            tracks += load_tracks(Path(args.tracks))
        if not tracks and args.no_grid:
            raise CheckError("nothing to draw: give --track or --tracks, or drop --no-grid")
        gray, bgr, note = load_frame(Path(args.image), cal, args.jpeg_quality)
        projector = ColumnProjector(cal, ColumnGeometry(
            settings.roi.column_height_m, settings.roi.column_half_width_m,
            settings.roi.padding_px))
        outs = check(gray, tracks, projector, settings)
    except (CheckError, ConfigError, VerifierConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for warning in cal.warnings():
        print(f"warning: calibration: {warning}", file=sys.stderr)
    if note:
        print(f"note: {args.image}: {note}", file=sys.stderr)
    if not args.no_grid:
        draw_grid(bgr, cal, settings)
    draw_tracks(bgr, projector, outs)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), bgr):
        print(f"error: cannot write {out}", file=sys.stderr)
        return 2
    print(f"calibration {args.calibration}, verifier {settings.verifier.name} "
          f"{settings.verifier.params or '(defaults)'}")
    print(table(outs, cal.width * cal.height))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
