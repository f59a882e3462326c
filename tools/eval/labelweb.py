"""`aeb label`: a local web page to label ROIs YES / NO / ambiguous with the keyboard.

    aeb label out/eval/drive --labels out/eval/drive/labels.tsv --who ana --sample 320

The sample is drawn stratified across edge-density bands and conditions (sampling.py)
and kept beside the label file (`<labels>.sample`), so that a session stopped at any
moment resumes where it was: labelled ROIs are never shown again, every label is on disk
before the page shows the next ROI. Each ROI is shown on its frame (green: the ROI;
blue: the projected column) with the ROI enlarged beside it. ROIs with ground truth (data
sets, simulator runs) are left out unless --include-truth.

Serves on 127.0.0.1:8780 by default (aeb foxglove's WebSocket has 8765). Exit codes: 0
stopped, 2 bad arguments or input, or the port in use.
"""

import argparse
import errno
import json
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import TYPE_CHECKING, Any

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.tools.commands import DEFAULT_PORTS, port_in_use
from aeb_radar_camera.tools.eval.label_page import PAGE
from aeb_radar_camera.tools.eval.labels import (
    AMBIGUOUS,
    NO,
    VALUES,
    YES,
    Label,
    LabelFileError,
    LabelWriter,
    now_utc,
    read_labels,
)
from aeb_radar_camera.tools.eval.records import RecordFileError, RoiRecord, read_records

# OpenCV, numpy and the sampling are imported where they are used: `aeb label --help`
# needs no extra installed
if TYPE_CHECKING:
    import numpy as np

ROI_BGR = (0, 255, 0)
COLUMN_BGR = (255, 128, 0)
CROP_SIDE_PX = 320


class LabelSession:
    """The labelling state (thread-safe): the sample, the labels, what to show next."""

    def __init__(self, items: list[RoiRecord], label_path: Path, who: str) -> None:
        self.items = items
        self.who = who
        self.labels = read_labels(label_path)
        self.writer = LabelWriter(label_path)
        self._lock = threading.Lock()
        self._queue = [i for i, r in enumerate(items) if r.id not in self.labels]
        self._history: list[int] = []
        self._skipped: set[int] = set()

    def close(self) -> None:
        self.writer.close()

    def _current(self) -> int | None:
        return self._queue[0] if self._queue else None

    def state(self) -> dict[str, Any]:
        with self._lock:
            return self._state()

    def _state(self) -> dict[str, Any]:
        values = [self.labels[r.id].value for r in self.items if r.id in self.labels]
        cur = self._current()
        current = None
        if cur is not None:
            r = self.items[cur]
            got = self.labels.get(r.id)
            # With ground truth, what the ROI was built from (an object, a background
            # patch, its class) is the answer: the page gets none of it, nor the id
            # that spells it (it still labels by it).
            hidden = r.truth is not None
            current = {"index": cur, "id": r.id, "truth_hidden": hidden,
                       "kind": None if hidden else r.kind,
                       "obj_class": None if hidden else r.obj_class,
                       "range_m": r.range_m, "ttc_s": r.ttc_s, "track_id": r.track_id,
                       "density": r.density, "lighting": r.lighting, "camera": r.camera,
                       "session": r.session, "frame": r.frame, "roi": list(r.roi),
                       "label": got.value if got else None}
        return {"total": len(self.items), "labelled": len(values),
                "yes": values.count(YES), "no": values.count(NO),
                "ambiguous": values.count(AMBIGUOUS),
                "skipped": len(self._skipped & set(self._queue)), "who": self.who,
                "current": current}

    def _check(self, roi_id: str) -> int:
        cur = self._current()
        if cur is None or self.items[cur].id != roi_id:
            raise ValueError(f"{roi_id!r} is not the ROI on screen")
        return cur

    def label(self, roi_id: str, value: str) -> dict[str, Any]:
        """Record a label for the ROI on screen and move on. Raises ValueError."""
        if value not in VALUES:
            raise ValueError(f"label {value!r} is not one of {', '.join(VALUES)}")
        with self._lock:
            cur = self._check(roi_id)
            label = Label(roi_id, value, self.who, now_utc())
            self.writer.add(label)
            self.labels[roi_id] = label
            self._queue.pop(0)
            self._history.append(cur)
            return self._state()

    def skip(self, roi_id: str) -> dict[str, Any]:
        """Show the ROI on screen again after the others. Raises ValueError."""
        with self._lock:
            cur = self._check(roi_id)
            self._queue.append(self._queue.pop(0))
            self._skipped.add(cur)
            self._history.append(cur)
            return self._state()

    def back(self, roi_id: str) -> dict[str, Any]:
        """Show the previous ROI again (to change its label)."""
        with self._lock:
            if self._history:
                prev = self._history.pop()
                if prev in self._queue:
                    self._queue.remove(prev)
                self._queue.insert(0, prev)
            return self._state()

    def frame_png(self, index: int) -> bytes:
        """The ROI's frame with its box. Raises IndexError, FrameLoadError."""
        import cv2
        import numpy as np

        from aeb_radar_camera.tools.eval.frames import load_bgr

        r = self.items[index]
        img = np.ascontiguousarray(load_bgr(r.frame_ref))
        cx, cy, cw, ch = r.column
        if r.column != r.roi:
            cv2.rectangle(img, (cx, cy), (cx + cw - 1, cy + ch - 1), COLUMN_BGR, 1)
        x, y, w, h = r.roi
        cv2.rectangle(img, (x, y), (x + w - 1, y + h - 1), ROI_BGR, 2)
        return _png(img)

    def crop_png(self, index: int) -> bytes:
        """The ROI alone, enlarged. Raises IndexError, FrameLoadError."""
        import cv2

        from aeb_radar_camera.tools.eval.frames import load_bgr

        r = self.items[index]
        img = load_bgr(r.frame_ref)
        x, y, w, h = r.roi
        crop = img[y:y + h, x:x + w]
        k = max(1, CROP_SIDE_PX // max(w, h))
        return _png(cv2.resize(crop, (w * k, h * k), interpolation=cv2.INTER_NEAREST))


def _png(img: "np.ndarray") -> bytes:
    import cv2

    from aeb_radar_camera.tools.eval.frames import FrameLoadError

    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise FrameLoadError("PNG encoding failed")
    return buf.tobytes()


def make_server(session: LabelSession, host: str = "127.0.0.1", port: int = 0
                ) -> ThreadingHTTPServer:
    """The page's HTTP server (not started); `server_address[1]` is its port."""
    from aeb_radar_camera.tools.eval.frames import FrameLoadError

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, format: str, *args: Any) -> None:   # quiet
            return

        def _send(self, code: int, body: bytes, ctype: str) -> None:
            self.send_response(code)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def _json(self, code: int, data: dict[str, Any]) -> None:
            self._send(code, json.dumps(data).encode(), "application/json")

        def do_GET(self) -> None:
            path = self.path.split("?", 1)[0]
            try:
                if path == "/":
                    self._send(200, PAGE.encode(), "text/html; charset=utf-8")
                elif path == "/api/state":
                    self._json(200, session.state())
                elif path.startswith(("/frame/", "/crop/")) and path.endswith(".png"):
                    index = int(path.rsplit("/", 1)[1][:-4])
                    body = (session.frame_png(index) if path.startswith("/frame/")
                            else session.crop_png(index))
                    self._send(200, body, "image/png")
                else:
                    self._send(404, b"not found", "text/plain")
            except (ValueError, IndexError) as exc:
                self._send(404, str(exc).encode(), "text/plain")
            except FrameLoadError as exc:
                self._send(500, str(exc).encode(), "text/plain")

        def do_POST(self) -> None:
            try:
                length = int(self.headers.get("Content-Length", "0"))
                body = json.loads(self.rfile.read(length) or b"{}")
                roi_id = str(body.get("id", ""))
                if self.path == "/api/label":
                    self._json(200, session.label(roi_id, str(body.get("value", ""))))
                elif self.path == "/api/skip":
                    self._json(200, session.skip(roi_id))
                elif self.path == "/api/back":
                    self._json(200, session.back(roi_id))
                else:
                    self._send(404, b"not found", "text/plain")
            except (ValueError, json.JSONDecodeError) as exc:
                self._json(409, {"error": str(exc), **session.state()})

    return ThreadingHTTPServer((host, port), Handler)


def pick_sample(records: list[RoiRecord], label_path: Path, n: int, keys: list[str],
                groups: list[tuple[str, str]], edges: tuple[float, ...], seed: int
                ) -> list[RoiRecord]:
    """The sample kept beside the label file, or a new stratified one (then kept)."""
    from aeb_radar_camera.tools.eval.sampling import stratified, stratum_key

    sample_path = label_path.with_name(label_path.name + ".sample")
    by_id = {r.id: r for r in records}
    if sample_path.is_file():
        ids = [ln.strip() for ln in sample_path.read_text().splitlines() if ln.strip()]
        if ids and all(i in by_id for i in ids):
            return [by_id[i] for i in ids]
    picked = (stratified(records, n, stratum_key(keys, groups, edges), seed) if n > 0
              else list(records))
    sample_path.parent.mkdir(parents=True, exist_ok=True)
    sample_path.write_text("".join(f"{r.id}\n" for r in picked))
    return picked


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="aeb label", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("rois", help="a ROI folder (rois.jsonl) or file from `aeb eval rois`")
    p.add_argument("--labels", help="label file (default: labels.tsv beside the ROIs)")
    p.add_argument("--who", default="anonymous", help="your name, written with each label")
    p.add_argument("--sample", type=int, default=320,
                   help="ROIs to label, stratified (0: every ROI); the paper drew 320")
    p.add_argument("--strata", default="lighting",
                   help="conditions crossed with the density bands: any of lighting, "
                        "group, kind, camera, session (comma-separated, '' for none)")
    p.add_argument("--edges", default="",
                   help="edge-density band edges (default: the sampling's, "
                        "tools/eval/sampling.py)")
    p.add_argument("--group", action="append", default=[], metavar="NAME=GLOB",
                   help="a session group (for --strata group)")
    p.add_argument("--include-truth", action="store_true",
                   help="also ROIs that have ground truth")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=DEFAULT_PORTS["label"],
                   help=f"default {DEFAULT_PORTS['label']} (aeb foxglove's is "
                        f"{DEFAULT_PORTS['foxglove']}); 0: any free port")
    add_log_level(p, "INFO")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("label", args.log_level)
    from aeb_radar_camera.common.service import stop_event_on_signals

    try:
        src = Path(args.rois)
        records = read_records(src)
        folder = src if src.is_dir() else src.parent
        label_path = Path(args.labels) if args.labels else folder / "labels.tsv"
        pool = [r for r in records if args.include_truth or r.truth is None]
        if not pool:
            raise ValueError("no ROI to label (every ROI has ground truth: "
                             "--include-truth to label them anyway)")
        groups = []
        for g in args.group:
            name, eq, pattern = g.rpartition("=")
            if not eq:
                raise ValueError(f"--group {g!r}: expected NAME=GLOB")
            groups.append((name, pattern))
        keys = [k.strip() for k in args.strata.split(",") if k.strip()]
        from aeb_radar_camera.tools.eval.sampling import DENSITY_EDGES

        edges = tuple(float(e) for e in args.edges.split(",") if e.strip()) or DENSITY_EDGES
        items = pick_sample(pool, label_path, args.sample, keys, groups, edges, args.seed)
        session = LabelSession(items, label_path, args.who)
        try:
            server = make_server(session, args.host, args.port)
        except OSError as exc:
            session.close()
            if exc.errno != errno.EADDRINUSE:
                raise
            raise ValueError(port_in_use("label", args.host, args.port)) from exc
    except (RecordFileError, LabelFileError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop = stop_event_on_signals()
    thread = threading.Thread(target=server.serve_forever, name="label-http", daemon=True)
    thread.start()
    st = session.state()
    print(f"label tool at http://{args.host}:{server.server_address[1]}/ - {st['labelled']} "
          f"of {st['total']} labelled, labels in {label_path} (Ctrl-C to stop)", flush=True)
    stop.wait()
    server.shutdown()
    server.server_close()
    session.close()
    st = session.state()
    print(f"stopped: {st['labelled']} of {st['total']} labelled in {label_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
