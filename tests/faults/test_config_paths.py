"""Found by `aeb faults fuzz` (mutated configurations): a path with a NUL byte, or a
name longer than the file system allows, escaped the config checks as ValueError /
OSError (a traceback and exit 1, which `aeb up` restarts forever) instead of a named
configuration error (exit 2)."""

import pytest

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, parse_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.services.radar.ports import ConfigurationError, check_settings


def test_a_nul_byte_in_a_config_path_is_a_config_error():
    with pytest.raises(ConfigError, match=r"fusion\.calibration"):
        parse_config({"fusion": {"calibration": "cal\x00.toml"}}, FusionConfig)


def test_a_replay_file_name_too_long_is_a_configuration_error():
    cfg = parse_config({"radar": {"can": {"interface": "replay"},
                                  "replay": {"file": "x" * 300}}}, RadarConfig)
    with pytest.raises(ConfigurationError, match="too long"):
        check_settings(cfg.radar.can, cfg.radar.replay)
