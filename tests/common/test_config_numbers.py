"""Every number of every service configuration: a random value either loads or raises
ConfigError naming the field - never another exception - and what loads can be built
into the brake's and fusion's cores. Non-finite numbers and contradictory brake timings
are rejected (exit code 2, the field named)."""

import contextlib
import subprocess
import sys
from typing import Any

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.camera import CameraConfig
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.brake.core import BrakeCore
from aeb_radar_camera.services.fusion.main import build_core
from aeb_radar_camera.services.fusion.verifiers import VerifierConfigError
from tests.support import REPO

# each type's shipped example (paths in it resolved): every field there, and the arrays
SHIPPED: dict[type[msgspec.Struct], str] = {
    BrakeConfig: "brake.toml", FusionConfig: "fusion.toml", RadarConfig: "radar.toml",
    CameraConfig: "camera-sim.toml"}
CONFIG_TYPES = list(SHIPPED)


def numeric_paths(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Where a number sits in a config's defaults (as builtins: tables and arrays)."""
    if isinstance(value, bool):
        return []
    if isinstance(value, (int, float)):
        return [path]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in numeric_paths(v, (*path, k))]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in numeric_paths(v, (*path, i))]
    return []


def with_value(tree: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(tree, list):
        return [with_value(v, rest, value) if i == head else v for i, v in enumerate(tree)]
    return {**tree, head: with_value(tree[head], rest, value)}


DEFAULTS = {t: msgspec.to_builtins(load_config(DEPLOY / f, t)) for t, f in SHIPPED.items()}
FIELDS = [(t, p) for t in CONFIG_TYPES for p in numeric_paths(DEFAULTS[t])]

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, -1, 0.0, -0.0, 1e-300, 1e300, 2**63, 2**64 - 1]),
)


def test_every_config_type_has_numbers_to_try():
    assert {t for t, _ in FIELDS} == set(CONFIG_TYPES)
    assert len(FIELDS) > 60


def _use(cfg: msgspec.Struct) -> None:
    """What a start builds from a config before any I/O."""
    if isinstance(cfg, BrakeConfig):
        BrakeCore(cfg.brake, "aeb/ego/fusion/primary/brake_cmd", 0, {})   # keys: not used here
    elif isinstance(cfg, FusionConfig):
        build_core(cfg)


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(field=st.sampled_from(FIELDS), value=numbers, second=st.sampled_from(FIELDS),
       other=numbers)
def test_a_random_number_in_any_field_loads_or_is_a_config_error(field, value, second, other):
    config_type, path = field
    data = with_value(DEFAULTS[config_type], path, value)
    if second[0] is config_type:
        data = with_value(data, second[1], other)
    try:
        cfg = parse_config(data, config_type)
    except ConfigError:
        return
    # VerifierConfigError: fusion's own check of its verifier's parameters (exit 2 too)
    with contextlib.suppress(VerifierConfigError):
        _use(cfg)


@pytest.mark.parametrize(("config_type", "table", "field"), [
    (BrakeConfig, "brake", "deadline_ms"),
    (BrakeConfig, "brake", "max_age_ms"),
    (BrakeConfig, "brake", "min_brake_hold_ms"),
    (FusionConfig, "fusion.frames", "max_skew_s"),
])
@pytest.mark.parametrize("value", [float("inf"), float("nan"), 1e300])
def test_a_non_finite_or_absurd_number_is_a_config_error_naming_the_field(
        config_type, table, field, value):
    data: dict[str, Any] = {}
    node = data
    for part in table.split("."):
        node = node.setdefault(part, {})
    node[field] = value
    with pytest.raises(ConfigError, match=field):
        parse_config(data, config_type)


def test_a_number_inside_a_free_form_table_must_be_finite_too():
    with pytest.raises(ConfigError, match=r"verifier\.params\.tau"):
        parse_config({"fusion": {"verifier": {"params": {"tau": float("inf")}}}}, FusionConfig)


@pytest.mark.parametrize(("brake", "named"), [
    ({"deadline_ms": 100.0, "max_age_ms": 150.0}, "max_age_ms"),
    ({"actuator": {"ttl_ms": 200, "ack_timeout_ms": 300.0}}, "ack_timeout_ms"),
])
def test_contradictory_brake_timings_are_rejected(brake, named):
    with pytest.raises(ConfigError, match=named):
        parse_config({"brake": brake}, BrakeConfig)


@pytest.mark.parametrize(("service", "text", "named"), [
    ("brake", "[brake]\ndeadline_ms = inf\n", "deadline_ms"),
    ("brake", "[brake]\nmin_brake_hold_ms = inf\n", "min_brake_hold_ms"),
    ("fusion", "[fusion.frames]\nmax_skew_s = inf\n", "max_skew_s"),
])
def test_an_inf_in_the_file_exits_2_naming_the_field(tmp_path, service, text, named):
    path = tmp_path / f"{service}.toml"
    path.write_text(text)
    res = subprocess.run([sys.executable, "-m", f"aeb_radar_camera.services.{service}", "--config",
                          str(path),
                          "--check"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert named in res.stderr and "Traceback" not in res.stderr
