"""The closed loop follows the fusion config it is given: the brake follows that
config's instance (`aeb demo --fusion-config deploy/fusion-paper.toml`)."""

import tomllib

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.demo import parse_args
from aeb_radar_camera.tools.sim.stack import FUSION_CONFIG, fusion_instance, write_configs


def test_the_brake_follows_the_instance_of_the_given_fusion_config(tmp_path):
    paper = DEPLOY / "fusion-paper.toml"
    assert fusion_instance(FUSION_CONFIG) == "primary"
    assert fusion_instance(paper) == "paper"
    configs = write_configs(tmp_path, "tcp/127.0.0.1:7447", "/dev/null", "/dev/null",
                            fusion_config=paper, fusion_instance=fusion_instance(paper))
    brake = tomllib.loads(configs.brake.read_text())
    fusion = tomllib.loads(configs.fusion.read_text())
    assert brake["brake"]["instance"] == fusion["fusion"]["instance"] == "paper"
    assert parse_args(["--fusion-config", str(paper)]).fusion_config == paper
    assert parse_args([]).fusion_config == FUSION_CONFIG
