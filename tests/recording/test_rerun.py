"""`aeb rerun`: fusion's and the radar's pure cores over a recording, offline.

The regression test of fusion's behaviour is here: fusion re-run on a simulator
recording kept in tests/data/recording/ must show exactly the differences declared
beside it, no more and no fewer. A change that changes fusion's behaviour declares its
differences there (`aeb rerun fusion REC --compare --write-expected FILE`) and says why.
"""

import hashlib
import json
import subprocess
import threading

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.config.radar import (
    CanSettings,
    Pace,
    RadarSettings,
    RawCanSettings,
    ReplaySettings,
)
from aeb_radar_camera.common.keys import RADAR_CAN, RADAR_TRACKS
from aeb_radar_camera.common.messages import (
    RawCanFrames,
    Verification,
    VerifiedTargets,
    decode,
    encode,
)
from aeb_radar_camera.services.radar.shell import RadarShell
from aeb_radar_camera.tools.recording.compare import Difference, check_declared
from aeb_radar_camera.tools.recording.depth import message_head
from aeb_radar_camera.tools.recording.format import channel_of_topic, stack_channel
from aeb_radar_camera.tools.recording.reader import Recording
from aeb_radar_camera.tools.recording.rerun_fusion import FusionRerun, normalised
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from tests.can_support import RECORDING, RECORDING_CYCLES
from tests.support import REPO, python_module
from tests.system.messages import radar_tracks, track

DATA = REPO / "tests" / "data" / "recording"
SIM = DATA / "pedestrian_standing_20kph.mcap"
DECLARED = DATA / "pedestrian_standing_20kph.rerun-fusion.json"
# The recording was made with the combined verifier: re-run with its config.
RECORDED_CONFIG = REPO / "deploy" / "fusion-combined.toml"
AS_RECORDED = ("-c", str(RECORDED_CONFIG), "--instance", "primary")


def rerun(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(python_module("aeb_radar_camera.tools.cli", "rerun", *args),
                          capture_output=True,
                          text=True, timeout=timeout, cwd=REPO)


def test_fusion_rerun_on_the_simulator_recording_shows_only_the_declared_differences(tmp_path):
    out = tmp_path / "found.json"
    proc = rerun("fusion", str(SIM), *AS_RECORDED, "--compare", "--expect", str(DECLARED),
                 "--quiet",
                 "--write-expected", str(out))
    declared = [Difference.from_json(d) for d in json.loads(DECLARED.read_text())["differences"]]
    found = [Difference.from_json(d) for d in json.loads(out.read_text())["differences"]]
    undeclared, missing = check_declared(found, declared)
    assert not undeclared and not missing, proc.stdout
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "no difference" in proc.stdout
    # Not vacuous: the recording warns, brakes and holds.
    rec = Recording.open(SIM)
    decisions = [r.data for r in rec.records(["aeb/ego/fusion/primary/brake_cmd"])]
    assert len(decisions) == 83


def test_fusion_rerun_is_deterministic_to_the_byte(tmp_path):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    for path in (a, b):
        proc = rerun("fusion", str(SIM), "-o", str(path), "--quiet")
        assert proc.returncode == 0, proc.stderr
    assert hashlib.sha256(a.read_bytes()).digest() == hashlib.sha256(b.read_bytes()).digest()
    channels = Recording.open(a).channels()
    assert channels["aeb/ego/fusion/rerun/brake_cmd"].messages == 83
    assert channels["/foxglove/ego/fusion/rerun/annotations/front"].messages > 10


# The combined verifier's score of the standing pedestrian is about 1.55 in this recording.
TAU = 1.55


def test_another_threshold_gives_the_expected_differences(tmp_path):
    result = tmp_path / "result.json"
    proc = rerun("fusion", str(SIM), *AS_RECORDED, "--compare", "--quiet", "--json",
                 str(result),
                 "--set", f"fusion.verifier.params.tau={TAU}")
    assert proc.returncode == 1          # differences, none declared
    assert f"tau={TAU}" in proc.stdout
    # Every track verified live with a score below TAU is now rejected; nothing else
    # changes its verification, and cycles that braked on one of them no longer brake.
    run = FusionRerun(load_config(RECORDED_CONFIG, FusionConfig), "primary")
    lower = [(c.tracks.header.seq, t.track_id) for c in run.run(Recording.open(SIM))
             if c.recorded is not None for t in c.recorded.targets
             if t.verification is Verification.VERIFIED and (t.density or 0) < TAU]
    assert lower
    fields = json.loads(result.read_text())["comparison"]["fields"]
    assert fields["densities.verification"] == len(lower)
    assert fields["decisions.decision"] > 0 and fields["commands.decision"] > 0
    assert "densities.density" not in fields       # the same frames, the same densities


def test_the_rerun_decodes_only_the_frames_cycles_use():
    cfg = load_config(REPO / "deploy" / "fusion.toml", FusionConfig)
    run = FusionRerun(cfg)
    cycles = list(run.run(Recording.open(SIM)))
    assert len(cycles) == 83
    st = run.stats
    gated = sum(1 for c in cycles if c.result is not None
                for t in normalised(c.result).targets.targets if t.density is not None)
    assert 0 < st.frames_decoded <= gated < st.frames_in_recording
    assert st.frames_pinned >= gated


def test_radar_rerun_on_the_simulator_recording_has_no_difference():
    # recorded with the paper's 25 m prefilter (its README); deploy/radar.toml passes 80 m
    proc = rerun("radar", str(SIM), "--compare", "--quiet",
                 "--set", "radar.prefilter.max_range_m=25")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "cycles compared: 83, with a difference: 0" in proc.stdout


def test_radar_rerun_on_the_real_ars408_drive_reproduces_its_tracks(tmp_path):
    """The real recording through the radar service's shell with its raw frames
    published, both into an MCAP; the re-run gives the same cycles."""
    path = tmp_path / "ars408.mcap"
    settings = RadarSettings(can=CanSettings(interface="replay"),
                             replay=ReplaySettings(file=str(RECORDING), pace=Pace.FAST,
                                                   exit_at_end=True),
                             raw_can=RawCanSettings(publish=True))
    writer = RecordingWriter(path, metadata={"vehicle": "ego"})
    lock = threading.Lock()
    t = [0]

    def put(topic, msg, stamp):
        with lock:
            t[0] += 1
            writer.write(topic, stack_channel(type(msg)), encode(msg), stamp + t[0], stamp)

    class Out:
        def tracks(self, sensor, msg):
            put(RADAR_TRACKS.key("ego", sensor=sensor), msg, msg.header.stamp_ns)

        def status(self, sensor, msg):
            pass

        def serving(self):
            pass

    def raw(batch: RawCanFrames) -> None:
        put(RADAR_CAN.key("ego", bus="radar"), batch, batch.frames[-1].rx_wall_ns)

    assert RadarShell(settings, Out(), raw_can=raw).run(threading.Event()) == 0
    writer.close()
    proc = rerun("radar", str(path), "--compare", "--quiet")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"cycles compared: {RECORDING_CYCLES}, with a difference: 0" in proc.stdout
    assert "no difference" in proc.stdout


def test_a_recording_without_raw_can_is_refused_for_the_radar(tmp_path):
    path = tmp_path / "no-can.mcap"
    with RecordingWriter(path) as w:
        msg = radar_tracks(0, (track(1, 10.0),), stamp_ns=10**18)
        w.write(RADAR_TRACKS.key("ego", sensor="front"), stack_channel(type(msg)), encode(msg),
                10**18, 10**18)
    proc = rerun("radar", str(path))
    assert proc.returncode == 2 and "no raw CAN frames" in proc.stderr


def test_numbers_compare_to_rounding_unless_exact():
    import msgspec

    from aeb_radar_camera.tools.recording.compare import Comparison

    recorded = radar_tracks(1, (track(1, x=12.0),))
    t = recorded.tracks[0]
    last_bit = msgspec.structs.replace(t, x_m=t.x_m * (1 + 2e-16))
    moved = msgspec.structs.replace(t, x_m=t.x_m + 1e-4)
    for rerun, rounded, exact in ((last_bit, 0, 1), (moved, 1, 1)):
        other = msgspec.structs.replace(recorded, tracks=(rerun,))
        assert len(Comparison().add_tracks(1, 0, recorded, other)) == rounded
        assert len(Comparison(exact=True).add_tracks(1, 0, recorded, other)) == exact


def _rewrite(src: Recording, out, keep=lambda rec: True, extra=()) -> None:
    """`src`'s records for which `keep` holds, and `extra` records, in log order."""
    records = sorted([*(r for r in src.records() if keep(r)), *extra],
                     key=lambda r: r.log_time_ns)
    with RecordingWriter(out, metadata=src.metadata(), flush_s=None) as writer:
        for r in records:
            writer.write(r.topic, channel_of_topic(r.topic), r.data, r.log_time_ns,
                         r.publish_time_ns, r.sequence)


def _first_frame_checked_with_depth() -> int:
    """The capture stamp of the first frame live fusion checked a track in with its
    depth, in the kept recording."""
    rec = Recording.open(SIM)
    stamps = {message_head(r.data).seq: message_head(r.data).stamp_ns
              for r in rec.records(["aeb/ego/camera/front/jpeg"])}
    for r in rec.records(["aeb/ego/fusion/primary/targets"]):
        for t in decode(r.data, VerifiedTargets).targets:
            if t.gate_detail.get("depth_available") == 1.0 and t.frame_seq is not None:
                return stamps[t.frame_seq]
    raise AssertionError("no frame checked with depth")


def _without_depth_of(stamp: int):
    return lambda r: not (r.topic == "aeb/ego/camera/front/depth"
                          and message_head(r.data).stamp_ns == stamp)


def test_a_frame_whose_depth_live_fusion_had_not_yet_is_rerun_without_it(tmp_path):
    # Live fusion checked a frame before its depth had reached it (the depth arrived,
    # and was recorded, just before the cycle): its outputs say `depth_available` 0.
    # Made from the kept recording: its inputs whole, its outputs those of fusion
    # without that depth.
    stamp = _first_frame_checked_with_depth()
    no_depth, live = tmp_path / "no_depth.mcap", tmp_path / "live.mcap"
    _rewrite(Recording.open(SIM), no_depth, _without_depth_of(stamp))
    proc = rerun("fusion", str(no_depth), *AS_RECORDED, "-o", str(tmp_path / "outputs.mcap"),
                 "--out-instance", "primary", "--no-views", "--quiet")
    assert proc.returncode == 0, proc.stderr
    outputs = list(Recording.open(tmp_path / "outputs.mcap").records())
    recorded_outputs = ("aeb/ego/fusion/primary/targets", "aeb/ego/fusion/primary/brake_cmd")
    _rewrite(Recording.open(SIM), live, lambda r: r.topic not in recorded_outputs, outputs)
    assert any(r.topic == "aeb/ego/camera/front/depth" and message_head(r.data).stamp_ns
               == stamp for r in Recording.open(live).records())

    proc = rerun("fusion", str(live), *AS_RECORDED, "--compare", "--quiet", "--json",
                 str(tmp_path / "result.json"))
    assert proc.returncode == 0 and "no difference" in proc.stdout, proc.stdout
    timing = json.loads((tmp_path / "result.json").read_text())["timing"]
    assert timing["depth_pinned"] > 0 and timing["depth_missing"] == 0


def test_depth_the_live_instance_had_but_the_recording_lacks_is_said(tmp_path):
    stamp = _first_frame_checked_with_depth()
    lacking = tmp_path / "lacking.mcap"
    _rewrite(Recording.open(SIM), lacking, _without_depth_of(stamp))
    proc = rerun("fusion", str(lacking), *AS_RECORDED, "--compare", "--quiet")
    assert "1 frame(s) had their depth in the live instance, but the recording does not " \
           "hold it" in proc.stdout, proc.stdout


def test_evidence_shows_the_default_checks_llr_per_cycle():
    # The shipped recall_first on the recording's standing pedestrian: depth confirms
    # it, and its sum climbs to the ceiling. The recording was braked early by the
    # paper's rule (the ego stops 15 m short): under the kinematic rule it never needs
    # to brake, so the paper's rule is set to see the BRAKE the evidence allows.
    proc = rerun("fusion", str(SIM), "--evidence", "--quiet",
                 "--set", "fusion.decision.rule=paper")
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stdout.splitlines() if line.startswith("t=")]
    assert lines and all(" llr " in line and " sum " in line for line in lines)
    assert any("depth_confirms" in line and "sum +4.00" in line for line in lines), lines
    assert any("BRAKE" in line for line in lines)


def test_comparing_nothing_fails_naming_the_recorded_instance():
    # the paper's config is instance `paper`; the recording holds `primary`'s outputs
    proc = rerun("fusion", str(SIM), "--compare", "--quiet", "-c",
                 str(REPO / "deploy" / "fusion-paper.toml"))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "nothing compared" in proc.stderr and "fusion instance 'paper'" in proc.stderr
    assert "it holds instance 'primary'" in proc.stderr
    assert "no difference" not in proc.stdout
