"""Real-time settings reach every process: the service tables accept `[*.realtime]`, the
launcher passes the router's priority, the simulated stack writes the same priority for
radar, fusion and brake (replacing whatever the shipped fusion config says)."""

import textwrap
import tomllib
from pathlib import Path

import msgspec
import pytest

from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.tools.launch.table import load_table, resolve_launches
from aeb_radar_camera.tools.sim.stack import FUSION_CONFIG, with_realtime, write_configs


@pytest.mark.parametrize(("config", "table"), [(RadarConfig, "radar"), (BrakeConfig, "brake"),
                                               (FusionConfig, "fusion")])
def test_each_service_takes_a_realtime_table_and_rejects_bad_priorities(config, table):
    cfg = parse_config({table: {"realtime": {"priority": 20}}}, config)
    assert getattr(cfg, table).realtime.priority == 20
    assert getattr(parse_config({}, config), table).realtime.priority == 0
    with pytest.raises(ConfigError, match="priority"):
        parse_config({table: {"realtime": {"priority": 100}}}, config)
    with pytest.raises(ConfigError, match="unknown"):
        parse_config({table: {"realtime": {"policy": "rr"}}}, config)


def test_the_launcher_gives_the_router_its_priority(tmp_path: Path):
    path = tmp_path / "table.toml"
    path.write_text(textwrap.dedent("""
        [router]
        listen = ["tcp/127.0.0.1:7999"]
        realtime_priority = 20
        """))
    table, workdir = load_table(path)
    router = resolve_launches(table, workdir, "test")[0]
    i = router.argv.index("--realtime-priority")
    assert router.argv[i + 1] == "20"
    path.write_text('[router]\nlisten = ["tcp/127.0.0.1:7999"]\n')
    table, workdir = load_table(path)
    assert "--realtime-priority" not in resolve_launches(table, workdir, "test")[0].argv


def test_the_simulated_stack_writes_one_priority_for_radar_fusion_and_brake(tmp_path: Path):
    configs = write_configs(tmp_path, "tcp/127.0.0.1:7447", "/dev/null", "/dev/pts/0",
                            realtime_priority=15)
    radar = load_config(configs.radar, RadarConfig)
    fusion = load_config(configs.fusion, FusionConfig)
    brake = load_config(configs.brake, BrakeConfig)
    assert (radar.radar.realtime.priority, fusion.fusion.realtime.priority,
            brake.brake.realtime.priority) == (15,) * 3
    shipped = load_config(FUSION_CONFIG, FusionConfig)
    # the rest of the shipped fusion config is unchanged
    assert msgspec.structs.replace(fusion.fusion, realtime=shipped.fusion.realtime) \
        == shipped.fusion
    off = write_configs(tmp_path / "off", "tcp/127.0.0.1:7447", "/dev/null", "/dev/pts/0")
    assert load_config(off.fusion, FusionConfig).fusion.realtime.priority == 0
    assert load_config(off.radar, RadarConfig).radar.realtime.priority == 0


def test_with_realtime_replaces_the_table_and_keeps_the_others():
    text = "a = 1\n[fusion]\nx = 2\n[fusion.realtime]  # old\npriority = 50\n[fusion.roi]\ny = 3\n"
    out = tomllib.loads(with_realtime(text, "fusion", 9))
    assert out == {"a": 1, "fusion": {"x": 2, "roi": {"y": 3}, "realtime": {"priority": 9}}}
