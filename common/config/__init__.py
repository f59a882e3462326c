"""Service configuration: TOML files validated at start (see `loader`)."""

from common.config.base import LogSettings, ServiceConfig, ZenohMode, ZenohSettings
from common.config.loader import ConfigError, load_config, load_config_or_exit

__all__ = [
    "ConfigError",
    "LogSettings",
    "ServiceConfig",
    "ZenohMode",
    "ZenohSettings",
    "load_config",
    "load_config_or_exit",
]
