"""Property tests (hypothesis) of every parser the services run on outside input: any
input gives a result or a counted, documented rejection, never another exception. The
long plain-loop run of the same targets is `aeb faults fuzz` (tools/faults/fuzz.py)."""

import contextlib
import math
import random
import tomllib
from pathlib import Path

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aeb_radar_camera.common.command_auth import KeyFileError
from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.loader import ConfigError, parse_config
from aeb_radar_camera.common.config.radar import EgoMotionSettings, RadarSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import EgoMotion, Header
from aeb_radar_camera.common.messages.codec import DecodeError, decode
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.brake.core import BrakeCore
from aeb_radar_camera.services.brake.protocol import BadLine, LineReader, ProtocolError
from aeb_radar_camera.services.brake.protocol import decode as decode_line
from aeb_radar_camera.services.radar.ars408.table import ID_TABLE, classify
from aeb_radar_camera.services.radar.core import RadarCore
from aeb_radar_camera.services.radar.ego import EgoMotionForwarder
from aeb_radar_camera.tools.faults import fuzz
from aeb_radar_camera.tools.faults.mutate import EXTREMES, mutate_bytes, mutate_tree
from aeb_radar_camera.tools.faults.samples import example, message_types

FAST = settings(max_examples=200, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])
ARS408_IDS = sorted(ID_TABLE)
frames = st.lists(st.tuples(st.one_of(st.sampled_from(ARS408_IDS), st.integers(0, 0x7FF)),
                            st.binary(max_size=12)), max_size=60)


@FAST
@given(frames)
def test_radar_core_counts_every_frame_it_cannot_use(seq):
    settings_ = RadarSettings()
    core = RadarCore(settings_.sensors[0], settings_)
    t = 1_000_000_000
    for arb_id, data in seq:
        t += 1_000_000
        found = classify(arb_id)
        if found is not None and found[1] == 0:
            core.on_frame(found[0], data, t / 1e9, t, t)
    core.poll(t + 5_000_000_000)
    assert core.frames_total == sum(1 for a, _ in seq if (f := classify(a)) and f[1] == 0)


@pytest.mark.parametrize("msg_type", message_types(), ids=lambda t: t.__name__)
@FAST
@given(data=st.data())
def test_every_message_type_decodes_or_raises_decode_error(msg_type, data):
    seed = msgspec.msgpack.encode(example(msg_type))
    payload = data.draw(st.one_of(
        st.binary(max_size=200),
        st.builds(lambda s: mutate_bytes(random.Random(s), seed),
                  st.integers(0, 2**32))))
    with contextlib.suppress(DecodeError):
        decode(payload, msg_type)


@FAST
@given(st.lists(st.binary(max_size=80), max_size=20))
def test_brake_serial_input_is_a_line_or_a_counted_bad_line(chunks):
    core = BrakeCore(BrakeConfig().brake, FUSION_BRAKE_CMD.key("ego", instance="primary"), 0,
                     fuzz.example_keyring())
    core.on_link(True, 0)
    reader = LineReader()
    now = 0
    for chunk in chunks:
        now += 1_000_000
        for item in reader.feed(chunk):
            if not isinstance(item, BadLine):
                with contextlib.suppress(ProtocolError):
                    decode_line(item, frozenset("AFN"))
            core.on_rx(item, now)
        core.on_tick(now)


@FAST
@given(st.binary(max_size=300), st.integers(0, 10**12))
def test_brake_command_payloads_are_accepted_or_rejected_by_reason(payload, rx):
    core = BrakeCore(BrakeConfig().brake, FUSION_BRAKE_CMD.key("ego", instance="primary"), 0,
                     fuzz.example_keyring())
    before = sum(core.rejected.values())
    core.on_command(payload, FUSION_BRAKE_CMD.key("ego", instance="primary"), rx, rx)
    assert core.last_rejection is not None
    assert sum(core.rejected.values()) == before + 1


finite_or_not = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                          st.sampled_from([math.nan, math.inf, -math.inf, 1e308]))


@FAST
@given(finite_or_not, finite_or_not)
def test_ego_motion_out_of_range_is_counted_not_raised(speed, yaw):
    fwd = EgoMotionForwarder(
        EgoMotionSettings(forward=True, max_age_s=10.0, min_interval_s=0.0), [0])
    msg = EgoMotion(Header(1, "vehicle", 0, 0), speed_mps=speed, yaw_rate_dps=yaw)
    frames_out = fwd.on_motion(msg, 0, 0)
    assert frames_out or fwd.rejected.total() == 1


@FAST
@given(st.integers(0, 2**32))
def test_mutated_brake_config_is_rejected_with_config_error_or_starts(seed):
    tree = tomllib.loads((DEPLOY / "brake.toml").read_text())
    mutated = mutate_tree(random.Random(seed), tree)
    with contextlib.suppress(ConfigError, KeyFileError):
        fuzz._start_objects("brake", _resolved(mutated))


def _resolved(tree: dict) -> BrakeConfig:
    from aeb_radar_camera.common.config.loader import resolve_paths
    return resolve_paths(parse_config(tree, BrakeConfig, "brake.toml"), DEPLOY)


@FAST
@given(st.binary(max_size=120))
def test_a_garbled_candump_line_never_escapes_the_replay_port(tmp_path_factory, junk):
    from aeb_radar_camera.services.radar.ports import Pace, ReplayPort
    path: Path = tmp_path_factory.mktemp("candump") / "replay.log"
    good = fuzz.candump_seed()[:2]
    path.write_bytes(good[0].encode() + junk + b"\n" + good[1].encode())
    port = ReplayPort(str(path), pace=Pace.FAST)
    got = 0
    while port.recv(0.0) is not None:
        got += 1
    port.shutdown()
    assert got >= 2


def test_extreme_values_include_what_broke_parsers_before():
    assert any(isinstance(v, float) and math.isinf(v) for v in EXTREMES)
    assert 2**64 - 1 in EXTREMES and 2**62 in EXTREMES


def test_the_fuzz_run_counts_every_input_and_finds_no_crash(tmp_path):
    tallies = fuzz.run(0.001, 7, list(fuzz.SCALES), lambda *a: None)
    assert {t.target.split(" ")[0] for t in tallies} >= {"can", "payloads", "mutated",
                                                          "serial", "candump"}
    for t in tallies:
        assert t.inputs > 0
        assert t.crashes == 0, (t.target, t.crash_samples)
        if t.target.startswith(("payloads", "mutated", "can ")):
            assert t.accepted + sum(t.rejected.values()) >= t.inputs - t.crashes, t.target
