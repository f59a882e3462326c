"""The radar's prefilter reaches as far as the fusion rule decides: tracks it drops are
tracks the rule never sees (tools/sim/radar_reach.py, deploy/radar.toml)."""

from pathlib import Path

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.config.radar import RadarConfig, RadarSettings
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.sim.radar_reach import radar_for
from aeb_radar_camera.tools.sim.stack import write_configs


def test_a_kinematic_fusion_widens_the_prefilter_to_its_range_gate_and_the_paper_keeps_25_m():
    kinematic = load_config(DEPLOY / "fusion.toml", FusionConfig)
    paper = load_config(DEPLOY / "fusion-paper.toml", FusionConfig)
    gate = kinematic.fusion.decision.kinematic.range_max_m
    assert radar_for(kinematic).prefilter.max_range_m == gate == 80.0
    assert radar_for(paper) == RadarSettings()
    assert radar_for(paper).prefilter.max_range_m == 25.0
    assert radar_for(paper, kinematic, None).prefilter.max_range_m == gate


def test_the_shipped_radar_config_sees_as_far_as_the_shipped_fusion_decides():
    shipped = load_config(DEPLOY / "radar.toml", RadarConfig).radar.prefilter.max_range_m
    fusion = load_config(DEPLOY / "fusion.toml", FusionConfig)
    assert shipped >= radar_for(fusion).prefilter.max_range_m


def test_the_simulated_stack_writes_the_prefilter_its_fusion_needs(tmp_path: Path):
    for name, reach in (("fusion.toml", 80.0), ("fusion-paper.toml", 25.0)):
        configs = write_configs(tmp_path / name, "tcp/127.0.0.1:7447", "/dev/null",
                                "/dev/pts/0", fusion_config=DEPLOY / name)
        radar = load_config(configs.radar, RadarConfig)
        assert radar.radar.prefilter.max_range_m == reach, name
