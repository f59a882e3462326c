"""`aeb faults fuzz` (`python -m aeb_radar_camera.tools.faults.fuzz`): a long plain-loop fuzz
of every
input the services parse, in-process, each through the code the service runs on it:

- CAN frames through the radar core (valid simulated cycles, mutated, and random IDs);
- payloads on every key through its decode path (the generic decoder, and the
  service's own handler where it has one: the brake's command validation and state
  machine, the radar's ego-motion forwarder, fusion's frame decoder and its core);
- mutated JPEGs through fusion's frame decoder;
- serial lines through the brake's line reader, protocol decoder and state machine;
- mutated candump lines through the radar's replay port;
- mutated configurations through each service's config loading and start-up objects.

A rejection is any documented refusal (a counted reason); a crash is any other
exception escaping that code. Prints progress, a table of counts, and writes it as JSON
(and Markdown) under --out. Exit code 0 with zero crashes, 1 otherwise.
"""

import argparse
import json
import logging
import math
import random
import sys
import tempfile
import time
import tomllib
import traceback
import warnings
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.camera import CameraConfig
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.imaging import encode_jpeg, jpeg_crc32
from aeb_radar_camera.common.keys import CAMERA_JPEG, EGO_MOTION, FUSION_BRAKE_CMD, RADAR_TRACKS
from aeb_radar_camera.common.keys import REGISTRY as KEYS
from aeb_radar_camera.common.messages import BrakeCommand, CompressedFrame, Decision, Header
from aeb_radar_camera.common.messages.codec import DecodeError, decode, encode
from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_KEYS
from aeb_radar_camera.tools.faults.mutate import mutate_bytes, mutate_msgpack, mutate_tree
from aeb_radar_camera.tools.faults.samples import example

SCALES = {"can": 1_000_000, "payloads": 100_000, "jpeg": 10_000, "serial": 100_000,
          "candump": 10_000, "config": 10_000}
CRASH_SAMPLES = 5
VEHICLE = "ego"


@dataclass
class Tally:
    """One target's counts: inputs, accepted, rejected by reason, crashes (with the
    first few inputs and tracebacks)."""

    target: str
    inputs: int = 0
    accepted: int = 0
    rejected: Counter[str] = field(default_factory=Counter)
    crashes: int = 0
    crash_samples: list[dict[str, str]] = field(default_factory=list)
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)

    def crash(self, data: object, exc: BaseException) -> None:
        self.crashes += 1
        if len(self.crash_samples) < CRASH_SAMPLES:
            shown = data.hex() if isinstance(data, bytes | bytearray) else repr(data)
            self.crash_samples.append({
                "input": shown[:400], "error": repr(exc)[:300],
                "where": "".join(traceback.format_tb(exc.__traceback__)[-2:])[-600:]})

    def as_dict(self) -> dict[str, Any]:
        return {"target": self.target, "inputs": self.inputs, "accepted": self.accepted,
                "rejected": sum(self.rejected.values()),
                "rejected_by_reason": dict(self.rejected.most_common()),
                "crashes": self.crashes, "crash_samples": self.crash_samples,
                "seconds": round(self.seconds, 1), "notes": self.notes}


Progress = Callable[[str, int, int], None]


def _quiet_logs() -> None:
    # the services log every rejection (rate-limited); a fuzz run would drown in them.
    # numpy's warnings on non-finite values are left out of the output too (not crashes)
    logging.getLogger().setLevel(logging.CRITICAL)
    warnings.simplefilter("ignore", RuntimeWarning)


# -- CAN frames through the radar core ------------------------------------------------


def simulated_cycles(n_cycles: int = 40) -> list[list[tuple[int, bytes]]]:
    """Valid ARS408 cycles (arbitration ID, data) from the SIMULATED radar in a scenario."""
    from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
    from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
    from aeb_radar_camera.tools.sim.world import World

    sent: list[list[tuple[int, bytes]]] = []

    class Sink:
        def send(self, frames: Any) -> None:
            sent.append([(f.arb_id, bytes(f.data)) for f in frames])

    sc = load_scenario(find_scenario("multi_object_25kph"))
    feed = RadarFeed(Sink(), sc.radar, seed=1, frame_time_s=0.0, sleep=lambda s: None,
                     yield_cpu=lambda: None)
    world = World(sc)
    for _ in range(n_cycles):
        world.step(0.075, 0.0)
        feed.cycle(world.bodies(), world.ego.x_m, world.ego.speed_mps)
    return [c for c in sent if c]


def fuzz_can(n: int, rng: random.Random, progress: Progress) -> Tally:
    from aeb_radar_camera.common.config.radar import RadarSettings
    from aeb_radar_camera.services.radar.ars408.table import ID_TABLE, classify
    from aeb_radar_camera.services.radar.core import RadarCore

    tally = Tally("can frames -> radar core")
    settings = RadarSettings()
    core = RadarCore(settings.sensors[0], settings)
    cycles = simulated_cycles()
    ids = sorted(ID_TABLE)
    mono = 1_000_000_000
    cycles_out = 0
    sent = 0
    while sent < n:
        cycle = list(rng.choice(cycles))
        kind = rng.randrange(4)
        if kind == 0:       # a valid cycle with some frames' bytes mutated
            frames = [(a, mutate_bytes(rng, d)[:8] if rng.random() < 0.2 else d)
                      for a, d in cycle]
        elif kind == 1:     # frames lost, repeated, reordered
            frames = [f for f in cycle if rng.random() > 0.1]
            frames += rng.sample(cycle, min(len(cycle), rng.randint(0, 5)))
            if rng.random() < 0.5:
                rng.shuffle(frames)
        elif kind == 2:     # random frames on ARS408 IDs of any sensor
            frames = [(rng.choice(ids), rng.randbytes(rng.randint(0, 8)))
                      for _ in range(rng.randint(1, 50))]
        else:               # random 11-bit IDs, any length (a CAN FD frame: up to 64)
            frames = [(rng.randrange(0x800), rng.randbytes(rng.choice((0, 1, 8, 12, 64))))
                      for _ in range(rng.randint(1, 50))]
        for arb_id, data in frames:
            mono += rng.randint(0, 400_000)
            tally.inputs += 1
            sent += 1
            try:
                found = classify(arb_id)
                if found is None or found[1] != 0:
                    tally.rejected["not_this_radar"] += 1
                    continue
                cycles_out += len(core.on_frame(found[0], data, mono / 1e9, mono, mono))
            except Exception as exc:
                tally.crash((arb_id, data), exc)
        if rng.random() < 0.05:
            mono += rng.randint(0, 2_000_000_000)   # the bus falls silent for a while
            try:
                cycles_out += len(core.poll(mono))
            except Exception as exc:
                tally.crash(("poll", mono), exc)
        progress(tally.target, sent, n)
    tally.rejected.update(core.rejected.snapshot())
    tally.accepted = tally.inputs - tally.rejected["not_this_radar"]
    tally.notes.append(f"{cycles_out} cycles tracked; core rejections by reason are "
                       "per frame or per cycle (assembly)")
    return tally


# -- payloads on every key ---------------------------------------------------------------


class _Consumers:
    """Each service's handler for the keys it consumes, built once."""

    def __init__(self) -> None:
        from aeb_radar_camera.common.config.radar import EgoMotionSettings
        from aeb_radar_camera.services.brake.core import BrakeCore
        from aeb_radar_camera.services.fusion.main import build_core
        from aeb_radar_camera.services.radar.ego import EgoMotionForwarder

        cfg = BrakeConfig()
        self.brake_key = FUSION_BRAKE_CMD.key(VEHICLE, instance=cfg.brake.instance)
        self.brake = BrakeCore(cfg.brake, self.brake_key, 0, example_keyring())
        self.ego = EgoMotionForwarder(EgoMotionSettings(forward=True, max_age_s=1e9,
                                                        min_interval_s=0.0),
                                      [0])
        fusion_cfg = load_config(DEPLOY / "fusion.toml", FusionConfig)
        self.fusion, cals = build_core(fusion_cfg)
        cal = next(iter(cals.values()))
        self.width, self.height = cal.width, cal.height
        self.now = 1_000_000_000

    def brake_command(self, payload: bytes, tally: Tally) -> None:
        self.now += 10_000_000
        self.brake.on_command(payload, self.brake_key, self.now, self.now)
        reason = self.brake.last_rejection
        if reason is None:
            tally.accepted += 1
        else:
            tally.rejected[reason.value] += 1

    def ego_motion(self, payload: bytes, tally: Tally) -> None:
        from aeb_radar_camera.common.messages import EgoMotion
        msg = decode(payload, EgoMotion)
        before = self.ego.rejected.total()
        self.ego.on_motion(msg, msg.header.stamp_ns, self.now)
        self.now += 1
        if self.ego.rejected.total() > before:
            tally.rejected["ego_rejected"] += 1
        else:
            tally.accepted += 1

    def camera_frame(self, payload: bytes, tally: Tally) -> None:
        from aeb_radar_camera.services.fusion.frames import FrameError, decode_frame
        try:
            decode_frame(payload, self.now, self.width, self.height)
        except FrameError as exc:
            tally.rejected[f"frame_{exc.reason}"] += 1
            return
        tally.accepted += 1

    def radar_tracks(self, payload: bytes, tally: Tally) -> None:
        from aeb_radar_camera.common.messages import RadarTracks
        from aeb_radar_camera.services.fusion.frames import FrameFeed
        tracks = decode(payload, RadarTracks)
        decided = self.fusion.decide(tracks, [FrameFeed()], tracks.header.stamp_ns, self.now)
        self.fusion.report(decided)
        tally.accepted += 1


def key_seeds() -> dict[str, bytes]:
    """A valid payload per key (the schema's example; a few keys with realistic values)."""
    seeds: dict[str, bytes] = {}
    for name, spec in KEYS.items():
        if spec.msg_type is not None:
            seeds[name] = encode(example(spec.msg_type))
    seeds[FUSION_BRAKE_CMD.name] = brake_command_seed(1, 0)
    return seeds


def example_keyring() -> dict[str, Any]:
    """The INSECURE example key of fusion `primary` (deploy/keys), as the sim stack uses."""
    from aeb_radar_camera.common.command_auth import load_keyring
    return load_keyring([str(EXAMPLE_KEYS / "primary.key")], "primary")


_signer: list[Any] = []


def sign(cmd: BrakeCommand) -> bytes:
    """`cmd` encoded and signed as fusion `primary` would."""
    from aeb_radar_camera.common.command_auth import CommandSigner
    if not _signer:
        _signer.append(CommandSigner(next(iter(example_keyring().values()))))
    payload: bytes = _signer[0].sign(cmd)
    return payload


def brake_command_seed(seq: int, pub_mono_ns: int) -> bytes:
    """A valid, signed command of fusion `primary` (the brake's default instance)."""
    fields = msgspec.structs.asdict(example(BrakeCommand))
    fields.update(header=Header(seq=seq, source="fusion/primary", stamp_ns=pub_mono_ns,
                                pub_mono_ns=pub_mono_ns),
                  instance="primary", decision=Decision.NONE, brake_level_pct=0.0, auth=None)
    return sign(BrakeCommand(**fields))


def resigned(payload: bytes) -> bytes:
    """A mutated command signed again when it still decodes (a fusion with a bug: the
    brake's checks after the MAC), else as it is."""
    try:
        cmd = decode(payload, BrakeCommand)
    except DecodeError:
        return payload
    try:
        return sign(msgspec.structs.replace(cmd, auth=None))
    except (ValueError, OverflowError, TypeError, msgspec.EncodeError):
        return payload


def fuzz_payloads(n: int, rng: random.Random, progress: Progress) -> list[Tally]:
    consumers = _Consumers()
    handlers: dict[str, Callable[[bytes, Tally], None]] = {
        FUSION_BRAKE_CMD.name: consumers.brake_command,
        EGO_MOTION.name: consumers.ego_motion,
        CAMERA_JPEG.name: consumers.camera_frame,
        RADAR_TRACKS.name: consumers.radar_tracks,
    }
    seeds = key_seeds()
    jpeg = seed_jpeg(consumers.width, consumers.height)
    seeds[CAMERA_JPEG.name] = encode(CompressedFrame(
        header=Header(1, "camera/front", 0, 0), camera="front", width=consumers.width,
        height=consumers.height, jpeg=jpeg, crc32=jpeg_crc32(jpeg)))
    tallies = []
    for name, seed in seeds.items():
        spec = KEYS[name]
        assert spec.msg_type is not None
        msg_type = spec.msg_type
        handler = handlers.get(name)
        where = "decode + " + handler.__name__ if handler else "decode"
        tally = Tally(f"payloads {spec.pattern} -> {where}")
        count = n if name != CAMERA_JPEG.name else max(1, n // 10)
        if count != n:
            tally.notes.append(f"{count} (a tenth: each decodes an 848x480 JPEG; the JPEG "
                               "target adds mutated images)")
        for i in range(count):
            if name == FUSION_BRAKE_CMD.name:
                # fresh: an old stamp would only ever be refused as too old
                seed = brake_command_seed(i, consumers.now + 10_000_000 - 1_000_000)
            payload = mutate_msgpack(rng, seed) if rng.random() < 0.95 else seed
            if name == FUSION_BRAKE_CMD.name and rng.random() < 0.5:
                payload = resigned(payload)
            tally.inputs += 1
            try:
                if handler is not None:
                    handler(payload, tally)
                else:
                    decode(payload, msg_type)
                    tally.accepted += 1
            except DecodeError:
                tally.rejected["undecodable"] += 1
            except Exception as exc:
                tally.crash(payload, exc)
            if i % 1000 == 0:
                progress(tally.target, i, count)
        tallies.append(tally)
    return tallies


# -- JPEGs ------------------------------------------------------------------------------


def seed_jpeg(width: int, height: int) -> bytes:
    """A JPEG with structure (gradients, edges, noise), as a camera's would have."""
    y, x = np.mgrid[0:height, 0:width]
    img = ((x * 255 // width + y * 128 // height) % 256).astype(np.uint8)
    img[height // 3:height // 2, width // 4:width // 2] = 30
    rng = np.random.default_rng(0)
    img = np.clip(img.astype(np.int16) + rng.integers(-8, 8, img.shape), 0, 255).astype(np.uint8)
    return encode_jpeg(np.dstack([img, img, img]), 80)


def fuzz_jpeg(n: int, rng: random.Random, progress: Progress) -> Tally:
    """Half the frames carry the CRC-32 the camera computed before the corruption (a
    frame damaged on its way), half none (a publisher that does not set it: not
    checked, so only the decoder stands between the bytes and the gate)."""
    from aeb_radar_camera.services.fusion.frames import FrameError, decode_frame
    tally = Tally("mutated jpegs -> fusion frame decoder")
    width, height = 848, 480
    seed = seed_jpeg(width, height)
    seed_crc = jpeg_crc32(seed)
    unchanged = 0
    accepted = Counter[str]()
    for i in range(n):
        jpeg = mutate_bytes(rng, seed) if rng.random() < 0.7 else _mutate_jpeg_body(rng, seed)
        unchanged += jpeg == seed
        with_crc = i % 2 == 0
        payload = encode(CompressedFrame(header=Header(i, "camera/front", 0, 0), camera="front",
                                         width=width, height=height, jpeg=jpeg,
                                         crc32=seed_crc if with_crc else None))
        tally.inputs += 1
        try:
            decode_frame(payload, i, width, height)
            tally.accepted += 1
            accepted["with_crc" if with_crc else "without_crc"] += jpeg != seed
        except FrameError as exc:
            tally.rejected[f"frame_{exc.reason}"] += 1
        except Exception as exc:
            tally.crash(jpeg[:64], exc)
        if i % 200 == 0:
            progress(tally.target, i, n)
    tally.notes.append(
        f"mutated JPEGs accepted (decoded to a frame): {accepted['with_crc']} of "
        f"{(n + 1) // 2} sent with the camera's CRC-32, {accepted['without_crc']} of "
        f"{n // 2} sent without one; {unchanged} mutations left the bytes unchanged")
    return tally


def _mutate_jpeg_body(rng: random.Random, jpeg: bytes) -> bytes:
    # one flipped bit in the entropy-coded data (after the headers): what a bad cable or
    # memory error does, and the case a decoder is most likely to accept
    b = bytearray(jpeg)
    start = jpeg.find(b"\xff\xda") + 20
    i = rng.randrange(start, len(b) - 2)
    b[i] ^= 1 << rng.randrange(8)
    return bytes(b)


# -- serial lines through the brake's protocol -----------------------------------------


def fuzz_serial(n: int, rng: random.Random, progress: Progress) -> Tally:
    from aeb_radar_camera.services.brake.core import BrakeCore
    from aeb_radar_camera.services.brake.protocol import (
        Ack,
        ActuatorState,
        BadLine,
        Fault,
        LineReader,
        Nak,
        ProtocolError,
    )
    from aeb_radar_camera.services.brake.protocol import decode as decode_line
    from aeb_radar_camera.services.brake.protocol import encode as encode_line

    tally = Tally("serial lines -> brake line reader, protocol, core")
    cfg = BrakeConfig()
    core = BrakeCore(cfg.brake, FUSION_BRAKE_CMD.key(VEHICLE, instance="primary"), 0,
                     example_keyring())
    core.on_link(True, 0)
    reader = LineReader()
    seeds = [encode_line(Ack(s, p, st)) for s in (0, 1, 9999) for p in (0.0, 55.5, 100.0)
             for st in ActuatorState]
    seeds += [encode_line(Fault(1, "watchdog")), encode_line(Nak(3, BadLine.CRC))]
    now = 0
    for i in range(n):
        line = rng.choice(seeds)
        data = mutate_bytes(rng, line) if rng.random() < 0.9 else line
        if rng.random() < 0.1:
            data = data.replace(b"\n", b"")      # a line split across reads
        tally.inputs += 1
        now += 1_000_000
        try:
            for item in reader.feed(data):
                if isinstance(item, BadLine):
                    tally.rejected[item.value] += 1
                else:
                    try:
                        decode_line(item, frozenset("AFN"))
                    except ProtocolError as exc:
                        tally.rejected[exc.reason.value] += 1
                    else:
                        tally.accepted += 1
                core.on_rx(item, now)
            core.on_tick(now)
        except Exception as exc:
            tally.crash(data, exc)
        if i % 5000 == 0:
            progress(tally.target, i, n)
    tally.notes.append("counts are lines out of the reader (one input may hold none or "
                       "several); core counters: " + json.dumps(
                           {k: v for k, v in core.counters.items() if k.startswith("rx_")}))
    return tally


# -- candump lines -------------------------------------------------------------------------


def candump_seed() -> list[str]:
    log = next((DEPLOY / "recordings" / "ars408").glob("candump-*.log"))
    with open(log) as f:
        return [next(f) for _ in range(50)]


def fuzz_candump(n: int, rng: random.Random, progress: Progress) -> Tally:
    from aeb_radar_camera.services.radar.ports import Pace, ReplayPort
    tally = Tally("candump lines -> radar replay port")
    lines = candump_seed()
    with tempfile.TemporaryDirectory(prefix="aeb-fuzz-") as tmp:
        path = Path(tmp) / "fuzz.log"
        for i in range(n):
            good = rng.sample(lines, 3)
            bad = rng.choice(lines).rstrip("\n").encode()
            bad = mutate_bytes(rng, bad)
            path.write_bytes("".join(good[:2]).encode() + bad + b"\n" + good[2].encode())
            tally.inputs += 1
            got = 0
            try:
                port = ReplayPort(str(path), pace=Pace.FAST)
                try:
                    while port.recv(0.0) is not None:
                        got += 1
                finally:
                    port.shutdown()
            except Exception as exc:
                tally.crash(bad, exc)
                continue
            if got == 4:
                tally.accepted += 1
            elif got == 3:
                tally.rejected["line_skipped"] += 1
            else:
                tally.rejected[f"frames_read_{got}_of_4"] += 1
            if i % 500 == 0:
                progress(tally.target, i, n)
    return tally


# -- configurations ---------------------------------------------------------------------


def _start_objects(name: str, cfg: Any) -> None:
    """What a service builds from its config at start, before any I/O. Raises what
    the service turns into exit code 2 (ConfigError and the service's own)."""
    if name == "brake":
        from aeb_radar_camera.common.command_auth import load_keyring
        from aeb_radar_camera.services.brake.core import BrakeCore
        keys = load_keyring(cfg.brake.command_keys, cfg.brake.instance)
        BrakeCore(cfg.brake, FUSION_BRAKE_CMD.key(VEHICLE, instance="primary"), 0, keys)
    elif name == "radar":
        from aeb_radar_camera.services.radar.core import RadarCore
        from aeb_radar_camera.services.radar.ports import check_settings
        check_settings(cfg.radar.can, cfg.radar.replay)
        for sensor in cfg.radar.sensors:
            RadarCore(sensor, cfg.radar)
    elif name == "fusion":
        from aeb_radar_camera.services.fusion.main import build_core
        build_core(cfg)


def fuzz_configs(n: int, rng: random.Random, progress: Progress) -> Tally:
    from aeb_radar_camera.common.command_auth import KeyFileError
    from aeb_radar_camera.common.config.loader import resolve_paths
    from aeb_radar_camera.services.fusion.verifiers import VerifierConfigError
    from aeb_radar_camera.services.radar.ports import ConfigurationError
    tally = Tally("mutated configs -> load + start-up objects")
    files: dict[str, tuple[Path, type[Any]]] = {
             "brake": (DEPLOY / "brake.toml", BrakeConfig),
             "radar": (DEPLOY / "radar-replay.toml", RadarConfig),
             "fusion": (DEPLOY / "fusion.toml", FusionConfig),
             "camera": (DEPLOY / "camera.toml", CameraConfig)}
    trees = {k: tomllib.loads(p.read_text()) for k, (p, _) in files.items()}
    names = sorted(files)
    for i in range(n):
        name = names[i % len(names)]
        path, cfg_type = files[name]
        tree = mutate_tree(rng, trees[name])
        tally.inputs += 1
        try:
            cfg: Any = resolve_paths(parse_config(tree, cfg_type, name), path.parent)
            _start_objects(name, cfg)
            tally.accepted += 1
        except (ConfigError, ConfigurationError, VerifierConfigError, KeyFileError) as exc:
            tally.rejected[f"{name}:{type(exc).__name__}"] += 1
        except Exception as exc:
            tally.crash(json.dumps(tree, default=repr)[:400], exc)
        if i % 500 == 0:
            progress(tally.target, i, n)
    return tally


# -- the run ------------------------------------------------------------------------------


def run(scale: float, seed: int, targets: list[str], progress: Progress) -> list[Tally]:
    rng = random.Random(seed)
    out: list[Tally] = []
    runners: dict[str, Callable[[int], list[Tally]]] = {
        "can": lambda k: [fuzz_can(k, rng, progress)],
        "payloads": lambda k: fuzz_payloads(k, rng, progress),
        "jpeg": lambda k: [fuzz_jpeg(k, rng, progress)],
        "serial": lambda k: [fuzz_serial(k, rng, progress)],
        "candump": lambda k: [fuzz_candump(k, rng, progress)],
        "config": lambda k: [fuzz_configs(k, rng, progress)],
    }
    for name in targets:
        t0 = time.monotonic()
        tallies = runners[name](max(1, math.ceil(SCALES[name] * scale)))
        for t in tallies:
            t.seconds = (time.monotonic() - t0) / len(tallies)
        out += tallies
    return out


def markdown(tallies: list[Tally]) -> str:
    rows = ["| target | inputs | accepted | rejected (counted) | crashes | top reasons |",
            "|---|---:|---:|---:|---:|---|"]
    for t in tallies:
        top = ", ".join(f"{r} {c}" for r, c in t.rejected.most_common(4))
        rows.append(f"| {t.target} | {t.inputs:,} | {t.accepted:,} | "
                    f"{sum(t.rejected.values()):,} | {t.crashes} | {top} |")
    return "\n".join(rows) + "\n"


def _iter_targets(spec: str) -> Iterator[str]:
    for name in spec.split(","):
        name = name.strip()
        if name not in SCALES:
            raise SystemExit(f"error: unknown target {name!r} (known: {', '.join(SCALES)})")
        yield name


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb faults fuzz", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scale", type=float, default=1.0,
                        help="fraction of the full counts (1: 1e6 CAN frames, 1e5 payloads "
                             "per key and serial lines, 1e4 JPEGs, candump lines, configs)")
    parser.add_argument("--targets", default=",".join(SCALES))
    parser.add_argument("--seed", type=int, default=19)
    parser.add_argument("--out", default="out/fuzz")
    args = parser.parse_args(argv)
    _quiet_logs()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    last = [0.0]

    def progress(target: str, done: int, total: int) -> None:
        now = time.monotonic()
        if now - last[0] >= 5.0:
            last[0] = now
            print(f"  {target}: {done:,} / {total:,}", flush=True)

    try:
        tallies = run(args.scale, args.seed, list(_iter_targets(args.targets)), progress)
    except KeyboardInterrupt:
        print("interrupted: no table written", file=sys.stderr)
        return 130
    table = markdown(tallies)
    print("\n" + table)
    for t in tallies:
        for note in t.notes:
            print(f"  {t.target}: {note}")
        for c in t.crash_samples:
            print(f"  CRASH {t.target}: {c['error']}\n    input {c['input'][:120]}")
    (out / "fuzz.json").write_text(json.dumps(
        {"seed": args.seed, "scale": args.scale, "targets": [t.as_dict() for t in tallies]},
        indent=1))
    (out / "fuzz.md").write_text(table)
    crashes = sum(t.crashes for t in tallies)
    print(f"{crashes} crashes in {sum(t.inputs for t in tallies):,} inputs; "
          f"{out / 'fuzz.json'}")
    return 0 if crashes == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
