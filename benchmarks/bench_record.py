"""Recording at nominal rates: does `aeb record` lose anything, and what does it cost?

A publisher process plays the stack at its nominal rates for `--minutes`: radar tracks
at 13.5 Hz (8 tracks) with their raw CAN batch (60 frames), camera frames at 30 fps
(848x480 JPEG, about 67 KB, 32 different frames in turn), fusion targets and command
every radar cycle, brake status every cycle, radar status and camera info at 1 Hz, ego
motion at 50 Hz. `aeb record` (every key, the Foxglove views, zstd) records it through a
router. Per key: messages published against messages in the file (read back with the
MCAP reader), and bytes per minute on disk; the recorder's CPU share.

Baseline, in the same run: a plain Zenoh subscriber on every key in this process,
counting what it receives (what delivery alone gives), and its CPU.

    python -m benchmarks.bench_record                 # 30 s (the suite's run)
    python -m benchmarks.bench_record --minutes 10    # the 10-minute loss run
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_INFO,
    CAMERA_JPEG,
    EGO_MOTION,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_CAN,
    RADAR_STATUS,
    RADAR_TRACKS,
    KeySpec,
)
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeState,
    BrakeStatus,
    BusState,
    CameraInfo,
    CanFrame,
    CompressedFrame,
    Decision,
    EgoMotion,
    FailsafePolicy,
    Header,
    OutputMode,
    RadarStatus,
    RadarTrack,
    RadarTracks,
    RawCanFrames,
    Verification,
    VerifiedTarget,
    VerifiedTargets,
    VerifierStatus,
)
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.tools.machine import machine_info
from benchmarks.figures import Figure
from benchmarks.proc_sampler import ProcSampler
from benchmarks.processes import stop_processes

RADAR_HZ = 13.5
CAMERA_FPS = 30.0
EGO_HZ = 50.0
W, H = 848, 480
DISTINCT_FRAMES = 32
QUICK_MINUTES = 0.5       # the suite's run (quick: 20 s)


def frames() -> list[bytes]:
    """Textured frames of about 67 KB at quality 80 (a D435 frame of a street is 50 to
    90 KB), all different so that compression finds no repeat."""
    y, x = np.mgrid[0:H, 0:W]
    out = []
    for seed in range(DISTINCT_FRAMES):
        rng = np.random.default_rng(seed)
        img = (128 + 60 * np.sin((x + seed) / 17.0) * np.cos(y / 23.0)
               + rng.normal(0, 6, (H, W))).clip(0, 255).astype(np.uint8)
        out.append(encode_jpeg(np.dstack([img, img, img]), 80))
    return out


def _h(seq: int, source: str, stamp: int) -> Header:
    return Header(seq=seq, source=source, stamp_ns=stamp, pub_mono_ns=mono_ns())


def publish(endpoint: str, seconds: float, out: Path) -> int:
    """The publisher process: nominal rates for `seconds`, then the counts per key."""
    jpegs = frames()
    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))
    counts: dict[str, int] = {}
    with Bus.open(settings, "ego", "bench/publisher") as bus:
        pubs: dict[str, Any] = {name: bus.publisher(spec, **params) for name, spec, params in (
            ("jpeg", CAMERA_JPEG, {"camera": "front"}), ("tracks", RADAR_TRACKS,
                                                         {"sensor": "front"}),
            ("can", RADAR_CAN, {"bus": "radar"}), ("targets", FUSION_TARGETS,
                                                   {"instance": "primary"}),
            ("cmd", FUSION_BRAKE_CMD, {"instance": "primary"}), ("brake", BRAKE_STATUS, {}),
            ("rstatus", RADAR_STATUS, {"sensor": "front"}),
            ("info", CAMERA_INFO, {"camera": "front"}), ("ego", EGO_MOTION, {}))}
        # Give the router time to learn the recorder's subscriptions (a start-up matter:
        # the run counts from the first message on).
        time.sleep(1.0)
        periods = {"jpeg": 1 / CAMERA_FPS, "radar": 1 / RADAR_HZ, "ego": 1 / EGO_HZ,
                   "slow": 1.0}
        t0 = time.monotonic()
        due = dict.fromkeys(periods, t0)
        seq = dict.fromkeys(periods, 0)
        while True:
            kind = min(due, key=due.__getitem__)
            if due[kind] - t0 >= seconds:
                break
            wait = due[kind] - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            now, k = wall_ns(), seq[kind]
            sent = _send(kind, k, now, pubs, jpegs)
            for key in sent:
                counts[key] = counts.get(key, 0) + 1
            seq[kind] += 1
            due[kind] = t0 + seq[kind] * periods[kind]
        # Closing the session at once may drop what is still queued on keys that drop
        # when congested (frames, raw CAN): let the queues drain first.
        time.sleep(1.0)
    out.write_text(json.dumps(counts))
    return 0


def _send(kind: str, k: int, now: int, pubs: dict[str, Any], jpegs: list[bytes]) -> list[str]:
    def put(name: str, msg: Any) -> str:
        pubs[name].put(msg)
        return str(pubs[name].key)

    if kind == "jpeg":
        return [put("jpeg", CompressedFrame(header=_h(k, "camera/front", now), camera="front",
                                            width=W, height=H,
                                            jpeg=jpegs[k % DISTINCT_FRAMES]))]
    if kind == "ego":
        return [put("ego", EgoMotion(_h(k, "vehicle", now), 8.0, 0.0))]
    if kind == "slow":
        return [put("rstatus", RadarStatus(
            header=_h(k, "radar/front", now), sensor="front", ready=True, not_ready_reason="",
            bus_state=BusState.ACTIVE, interface="slcan", channel="/dev/ttyACM0",
            radar_state=None, firmware="4.30.2", cycle_period_ms=74.0, frames_per_s=800.0,
            cycles_total=k, cycles_incomplete=0, bus_reopens=0, rejected={})),
            put("info", CameraInfo(
                header=_h(k, "camera/front", now), camera="front", width=W, height=H,
                k=(600.0, 0, 424.0, 0, 600.0, 240.0, 0, 0, 1.0), dist=(0.0,) * 5,
                r=(0, -1.0, 0, 0, 0, -1.0, 1.0, 0, 0), t_m=(0.0, 0.0, 0.0), fps=30.0,
                source="realsense", frames_published=k * 30, frames_dropped=0, read_errors=0,
                healthy=True, status=""))]
    tracks = tuple(RadarTrack(i, 5.0 + 2.5 * i, 0.3 * i - 1.0, -3.0, 0.1, 6.0 + 2.5 * i, -3.0,
                              5.0, i < 6, 5, 0, 0.1, 0.2) for i in range(8))
    mono = mono_ns()
    sent = [put("tracks", RadarTracks(
        header=_h(k, "radar/front", now), sensor="front", mode=OutputMode.OBJECTS,
        meas_counter=2 * k, complete=True, n_detections=8, n_prefiltered=8,
        last_frame_mono_ns=mono, processing_ns=300_000, tracks=tracks))]
    sent.append(put("can", RawCanFrames(
        _h(k, "radar/radar", now), "radar", "slcan", "/dev/ttyACM0",
        tuple(CanFrame(timestamp_s=k * 0.074 + i * 1e-4, rx_wall_ns=now, rx_mono_ns=mono,
                       arb_id=0x60B, data=bytes(8)) for i in range(60)))))
    targets = tuple(VerifiedTarget(
        track_id=t.track_id, x_m=t.x_m, y_m=t.y_m, range_m=t.range_m,
        range_rate_mps=t.range_rate_mps, in_path=abs(t.y_m) < 1.2,
        verification=Verification.VERIFIED if i < 3 else Verification.NOT_CHECKED,
        roi_xywh=(300 + 20 * i, 200, 40, 90) if i < 3 else (),
        density=0.06 if i < 3 else None, ttc_s=2.0 + i, ttc_eff_s=1.0 + i,
        decision=Decision.NONE, reason="no threat", frame_seq=k, frame_age_ms=12.0)
        for i, t in enumerate(tracks[:6]))
    sent.append(put("cmd", BrakeCommand(
        header=_h(k, "fusion/primary", now), instance="primary", decision=Decision.NONE,
        brake_level_pct=0.0, verifier_status=VerifierStatus.OK, held=False, track_id=-1,
        range_m=None, ttc_s=None, reason="no threat among 6 confirmed tracks", radar_seq=k,
        radar_last_frame_mono_ns=mono)))
    sent.append(put("targets", VerifiedTargets(
        header=_h(k, "fusion/primary", now), instance="primary", radar_sensor="front",
        radar_seq=k, verifier="edge_density",
        verifier_params={"low": 40, "high": 120, "tau": 0.025},
        verifier_status=VerifierStatus.OK, targets=targets, processing_ns=900_000,
        camera="front")))
    sent.append(put("brake", BrakeStatus(
        header=_h(k, "brake/main", now), state=BrakeState.ARMED, reason="commands arriving",
        instance="primary", policy=FailsafePolicy.HOLD, last_cmd_seq=k,
        commanded_level_pct=0.0, actuator_position_pct=0.0, actuator_state="OK",
        actuator_connected=True, cmd_to_serial_us=200.0, radar_to_serial_us=1500.0,
        rejected={}, counters={"acks": k})))
    return sent


class Counter:
    """The baseline: a plain subscriber counting samples per key."""

    def __init__(self, bus: Bus) -> None:
        self.counts: dict[str, int] = {}
        self._lock = threading.Lock()
        every: KeySpec[Any] = KeySpec("bench_all", "**", None, None, None, RADAR_TRACKS.qos)
        self.sub = bus.subscribe_raw(every, self._on)

    def _on(self, payload: bytes, key: str, rx: int) -> None:
        with self._lock:
            self.counts[key] = self.counts.get(key, 0) + 1


def measure(minutes: float, out_dir: Path) -> dict[str, Any]:
    from aeb_radar_camera.tools.recording.reader import Recording
    from aeb_radar_camera.tools.recording.recorder import RECORDER_STATUS

    work = out_dir / "record-bench"
    work.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mcap, summary, pub_out = work / "bench.mcap", work / "summary.json", work / "published.json"
    for p in (mcap, summary, pub_out):
        p.unlink(missing_ok=True)
    procs: list[subprocess.Popen[bytes]] = []
    try:
        router = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.common.router",
                                   "--listen", endpoint],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        procs.append(router)
        settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))
        with Bus.open(settings, "ego", "bench/record") as bus:
            counter = Counter(bus)
            up = threading.Event()
            bus.subscribe_health(lambda s, i, alive: up.set() if s == "record" and alive
                                 else None)
            rec = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.tools.cli", "record",
                                    "-o", str(mcap),
                                    "--connect", endpoint, "--summary-json", str(summary)],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            procs.append(rec)
            if not up.wait(120):
                raise RuntimeError("the recorder did not come up")
            pub = subprocess.Popen([sys.executable, "-m", "benchmarks.bench_record",
                                    "--publish", endpoint, "--seconds", str(minutes * 60),
                                    "--published", str(pub_out)])
            procs.append(pub)
            sampler = ProcSampler({"recorder": rec.pid, "baseline (this process)": os.getpid()})
            sampler.start()
            last = time.monotonic()
            while pub.poll() is None:
                time.sleep(1.0)
                if time.monotonic() - last >= 30:
                    last = time.monotonic()
                    print(f"  recording ... {sum(counter.counts.values())} messages so far",
                          flush=True)
            if pub.returncode != 0:
                raise RuntimeError("the publisher failed")
            usage = sampler.stop()
            published: dict[str, int] = json.loads(pub_out.read_text())
            # Until the recorder has written all that the plain subscriber received, and
            # the subscriber has received nothing new for 2 s (or a minute passes): the
            # baseline is the count that check was made against.
            deadline = time.monotonic() + 60
            dropped: dict[str, int] = {}
            baseline: dict[str, int] = {}
            quiet_since = time.monotonic()
            while time.monotonic() < deadline:
                seen = dict(counter.counts)
                if seen != baseline:
                    baseline, quiet_since = seen, time.monotonic()
                got = bus.query(RECORDER_STATUS, 2.0, instance=str(rec.pid))
                if got:
                    dropped = got[0][0].dropped
                if got and got[0][0].queued == 0 and all(
                        got[0][0].messages.get(k, 0) >= min(n, baseline.get(k, 0))
                        for k, n in published.items()) and (
                        baseline == published or time.monotonic() - quiet_since >= 2.0):
                    break
                time.sleep(0.2)
        rec.send_signal(signal.SIGINT)
        rec.wait(120)
        in_file = {t: c.messages for t, c in Recording.open(mcap).channels().items()}
        size = mcap.stat().st_size
        return {"published": published, "recorded": in_file, "baseline": baseline,
                "dropped": dropped,
                "bytes": size, "minutes": minutes,
                "recorder_cpu_pct": usage["recorder"].cpu_pct,
                "recorder_rss_mb": usage["recorder"].rss_max / 2**20,
                "baseline_cpu_pct": usage["baseline (this process)"].cpu_pct,
                "summary": json.loads(summary.read_text()), "file": str(mcap)}
    finally:
        stop_processes(procs)


def figures_from(m: dict[str, Any]) -> list[Figure]:
    figs = []
    minutes = m["minutes"]
    for key, n in sorted(m["published"].items()):
        got = m["recorded"].get(key, 0)
        base = m["baseline"].get(key, 0)
        figs.append(Figure(
            "record", f"lost {key.removeprefix('aeb/ego/')}", n - got, "messages",
            baseline="a plain subscriber, same run", baseline_value=n - base,
            target="0", target_met=got == n,
            note=f"published {n}, in the file {got}, plain subscriber {base}; the recorder's "
                 f"own count of missing sequence numbers "
                 f"{m['summary']['keys'].get(key, {}).get('dropped', '-')}"))
    figs.append(Figure("record", "file size", round(m["bytes"] / 1e6 / minutes, 1), "MB/min",
                       note=f"{m['bytes'] / 1e6:.0f} MB in {minutes:g} min, zstd, with the "
                            "Foxglove views"))
    figs.append(Figure("record", "recorder CPU", round(m["recorder_cpu_pct"], 1), "% of a core",
                       baseline="plain subscriber (counts only)",
                       baseline_value=round(m["baseline_cpu_pct"], 1),
                       note=f"RSS max {m['recorder_rss_mb']:.0f} MB"))
    return figs


def run(quick: bool, out_dir: Path, minutes: float | None = None) -> list[Figure]:
    m = measure(minutes or (1 / 3 if quick else QUICK_MINUTES), out_dir)
    Path(m["file"]).unlink(missing_ok=True)        # hundreds of MB: the counts are kept
    (out_dir / "bench_record.json").write_text(json.dumps(m, indent=1))
    return figures_from(m)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_record",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=QUICK_MINUTES)
    parser.add_argument("--out", default="out/bench")
    parser.add_argument("--publish", default="", help=argparse.SUPPRESS)
    parser.add_argument("--seconds", type=float, default=0.0, help=argparse.SUPPRESS)
    parser.add_argument("--published", default="", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.publish:
        return publish(args.publish, args.seconds, Path(args.published))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    figs = run(False, out, args.minutes)
    from benchmarks.report import print_table

    print_table(figs, sys.stdout)
    print(f"machine: {machine_info()['cpu']}; ({time.monotonic() - t0:.0f} s; "
          f"{out / 'bench_record.json'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
