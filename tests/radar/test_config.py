"""The [radar] configuration: defaults are the paper's, errors name the field, and the
example configs in deploy/ are valid."""

import re

import pytest

from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.config.radar import Pace, RadarConfig
from aeb_radar_camera.services.radar.ports import ConfigurationError, check_settings
from tests.support import REPO


def test_defaults_are_the_papers():
    cfg = parse_config({}, RadarConfig)
    p, t = cfg.radar.prefilter, cfg.radar.tracker
    assert (p.forward_only, p.min_range_m, p.max_range_m, p.min_rcs_dbsm) == (
        True, 0.0, 25.0, -20.0)
    assert t.confirm_hits == 3 and not t.drop_receding and cfg.radar.merge.enabled
    assert [s.name for s in cfg.radar.sensors] == ["front"]


@pytest.mark.parametrize("data, field", [
    ({"radar": {"tracker": {"confirm_hits": 0}}}, "radar.tracker.confirm_hits"),
    ({"radar": {"prefilter": {"max_range": 30}}}, "radar.prefilter"),
    ({"radar": {"sensors": [{"name": "a", "sensor_id": 8}]}}, "sensor_id"),
    ({"radar": {"sensors": [{"name": "a"}, {"name": "a", "sensor_id": 1}]}}, "duplicate"),
    ({"radar": {"sensors": [{"name": "a b"}]}}, "sensor name"),
    ({"radar": {"can": {"interface": "replay"}}}, "replay.file"),
    ({"radar": {"sensors": []}}, "at least one"),
    ({"radar": {"sensors": [{"configure": {"max_distance_m": 201}}]}}, "max_distance_m"),
])
def test_invalid_fields_are_named(data, field):
    with pytest.raises(ConfigError, match=re.escape(field)):
        parse_config(data, RadarConfig)


def test_unknown_interface_and_missing_replay_file_fail_fast():
    cfg = parse_config({"radar": {"can": {"interface": "nonesuch"}}}, RadarConfig)
    with pytest.raises(ConfigurationError, match="nonesuch"):
        check_settings(cfg.radar.can, cfg.radar.replay)
    cfg = parse_config({"radar": {"can": {"interface": "replay"},
                                  "replay": {"file": "/no/such.log"}}}, RadarConfig)
    with pytest.raises(ConfigurationError, match=re.escape("/no/such.log")):
        check_settings(cfg.radar.can, cfg.radar.replay)


def test_deploy_examples_are_valid(monkeypatch):
    monkeypatch.chdir(REPO)       # the replay example names the recording relative to it
    real = load_config(REPO / "deploy" / "radar.toml", RadarConfig)
    assert real.radar.can.interface == "socketcan"
    assert real.radar.sensors[0].configure.enabled
    check_settings(real.radar.can, real.radar.replay)
    replay = load_config(REPO / "deploy" / "radar-replay.toml", RadarConfig)
    assert replay.radar.can.interface == "replay"
    assert replay.radar.replay.pace is Pace.REALTIME and replay.radar.replay.loop
    check_settings(replay.radar.can, replay.radar.replay)
