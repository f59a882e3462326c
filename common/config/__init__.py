"""Service configuration: TOML files validated at start (see `loader`)."""

from aeb_radar_camera.common.config.base import LogSettings, ServiceConfig, ZenohMode, ZenohSettings
from aeb_radar_camera.common.config.loader import ConfigError, load_config, load_config_or_exit

__all__ = [
    "ConfigError",
    "LogSettings",
    "ServiceConfig",
    "ZenohMode",
    "ZenohSettings",
    "load_config",
    "load_config_or_exit",
]
