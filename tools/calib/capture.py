"""`aeb calib-capture`: save a camera frame and the radar cycle closest to it in time from
the live bus, for `aeb calib-check` (docs/calibration.md, step 2).

    aeb calib-capture --out capture/                 # camera front, radar front
    aeb calib-capture --out capture/ --camera left --radar front --max-skew-s 0.04
    aeb calib-check --calibration cal.toml --image capture/frame.jpg \\
        --tracks capture/tracks.msgpack --out capture/check.png

Takes a frame once a radar cycle measured before it has arrived, waits for the first
cycle measured after it, and pairs the frame with whichever of the two is nearer by
`header.stamp_ns`; a pair further apart than --max-skew-s is not saved and the next frame
is tried. Writes `frame.jpg` (the JPEG as published), `tracks.msgpack`
(the RadarTracks as on the bus), `tracks.json` (the same, readable) and `capture.json`
(keys, stamps, skew). For a target standing still the skew hardly matters; for a moving
one keep it well under a radar cycle.

Exit codes: 0 saved, 1 no pair within --timeout, 2 the bus or --out cannot be used.
"""

import argparse
import json
import sys
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import msgspec

from aeb_radar_camera.common.keys import CAMERA_JPEG, RADAR_TRACKS
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import CompressedFrame, RadarTracks, encode
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, open_bus

_KEEP_CYCLES = 64       # about 5 s of radar cycles to choose from


@dataclass(frozen=True)
class Pair:
    frame: CompressedFrame
    tracks: RadarTracks

    @property
    def skew_ns(self) -> int:
        """Radar cycle stamp minus frame stamp."""
        return self.tracks.header.stamp_ns - self.frame.header.stamp_ns


class Pairing:
    """The frame and its nearest radar cycle, from messages in arrival order. Pure: no
    clock, no bus; not thread-safe (the shell holds a lock)."""

    def __init__(self, max_skew_ns: int) -> None:
        self.max_skew_ns = max_skew_ns
        self.cycles: deque[RadarTracks] = deque(maxlen=_KEEP_CYCLES)
        self.waiting: CompressedFrame | None = None
        self.too_far = 0          # frames whose nearest cycle was beyond max_skew

    def add_frame(self, frame: CompressedFrame) -> Pair | None:
        if self.waiting is None:
            self.waiting = frame
        return self._pair()

    def add_cycle(self, tracks: RadarTracks) -> Pair | None:
        self.cycles.append(tracks)
        return self._pair()

    def _pair(self) -> Pair | None:
        frame = self.waiting
        if frame is None:
            return None
        stamp = frame.header.stamp_ns
        if not any(c.header.stamp_ns >= stamp for c in self.cycles):
            return None        # the nearest cycle may still come
        self.waiting = None
        if not any(c.header.stamp_ns <= stamp for c in self.cycles):
            return None        # the cycle before it was not seen: the next frame will do
        best = min(self.cycles, key=lambda c: abs(c.header.stamp_ns - stamp))
        pair = Pair(frame, best)
        if abs(pair.skew_ns) > self.max_skew_ns:
            self.too_far += 1
            return None
        return pair


def save(pair: Pair, out: Path, camera_key: str, radar_key: str) -> dict[str, object]:
    """Write the four files; returns what capture.json says. Raises OSError."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "frame.jpg").write_bytes(pair.frame.jpeg)
    (out / "tracks.msgpack").write_bytes(encode(pair.tracks))
    (out / "tracks.json").write_bytes(msgspec.json.format(msgspec.json.encode(pair.tracks)))
    tracks = pair.tracks.tracks
    meta: dict[str, object] = {
        "camera_key": camera_key, "radar_key": radar_key,
        "frame_seq": pair.frame.header.seq, "frame_stamp_ns": pair.frame.header.stamp_ns,
        "frame_size": [pair.frame.width, pair.frame.height],
        "radar_seq": pair.tracks.header.seq, "radar_stamp_ns": pair.tracks.header.stamp_ns,
        "skew_ms": pair.skew_ns / 1e6, "tracks": len(tracks),
        "confirmed": sum(t.confirmed for t in tracks),
    }
    (out / "capture.json").write_text(json.dumps(meta, indent=1) + "\n")
    return meta


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb calib-capture", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="folder to write the capture into")
    parser.add_argument("--camera", default="front", help="camera name (camera/<name>/jpeg)")
    parser.add_argument("--radar", default="front", help="radar name (radar/<name>/tracks)")
    parser.add_argument("--max-skew-s", type=float, default=0.05,
                        help="largest frame-to-cycle time difference saved (default 0.05)")
    parser.add_argument("--timeout", type=float, default=30.0,
                        help="give up after this many seconds without a pair")
    add_bus_args(parser)
    args = parser.parse_args(argv)
    setup_logging("calib-capture", args.log_level)
    if args.max_skew_s <= 0 or args.timeout <= 0:
        print("error: --max-skew-s and --timeout must be positive", file=sys.stderr)
        return 2
    pairing = Pairing(round(args.max_skew_s * 1e9))
    lock = threading.Lock()
    found: list[Pair] = []
    done = stop_event_on_signals()

    def offer(pair: Pair | None) -> None:
        if pair is not None and not found:
            found.append(pair)
            done.set()

    def on_frame(frame: CompressedFrame, key: str) -> None:
        with lock:
            offer(pairing.add_frame(frame))

    def on_tracks(tracks: RadarTracks, key: str) -> None:
        with lock:
            offer(pairing.add_cycle(tracks))

    bus = open_bus(args, "calib-capture", done)
    with bus:
        camera_key = bus.key(CAMERA_JPEG, camera=args.camera)
        radar_key = bus.key(RADAR_TRACKS, sensor=args.radar)
        bus.subscribe(RADAR_TRACKS, on_tracks, sensor=args.radar)
        bus.subscribe(CAMERA_JPEG, on_frame, camera=args.camera)
        print(f"waiting for a frame on {camera_key} and a radar cycle on {radar_key} ...",
              file=sys.stderr, flush=True)
        done.wait(args.timeout)
        with lock:
            pair = found[0] if found else None
            cycles, too_far = len(pairing.cycles), pairing.too_far
    if pair is None:
        print(f"error: no frame and radar cycle within {args.max_skew_s:g} s of each other "
              f"in {args.timeout:g} s ({cycles} radar cycles seen, {too_far} frames too far "
              "from every cycle)", file=sys.stderr)
        return 1
    out = Path(args.out)
    try:
        meta = save(pair, out, camera_key, radar_key)
    except OSError as exc:
        print(f"error: {out}: {exc.strerror}", file=sys.stderr)
        return 2
    print(f"saved frame seq {meta['frame_seq']} and radar cycle seq {meta['radar_seq']} "
          f"({meta['tracks']} tracks, {meta['confirmed']} confirmed), "
          f"{pair.skew_ns / 1e6:+.1f} ms apart, to {out}/\n"
          f"check: aeb calib-check --calibration CALIBRATION.toml --image {out}/frame.jpg "
          f"--tracks {out}/tracks.msgpack --out {out}/check.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
