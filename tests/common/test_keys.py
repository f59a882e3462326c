import pytest

from aeb_radar_camera.common.keys import (
    FUSION_BRAKE_CMD,
    HEALTH,
    RADAR_TRACKS,
    REGISTRY,
    Congestion,
    Priority,
)


def test_keys_live_under_the_vehicle_prefix():
    assert RADAR_TRACKS.key("ego", sensor="front") == "aeb/ego/radar/front/tracks"
    assert FUSION_BRAKE_CMD.key("car2", instance="candidate") == (
        "aeb/car2/fusion/candidate/brake_cmd")


def test_missing_or_extra_parameters_are_errors():
    with pytest.raises(ValueError, match="needs parameters"):
        RADAR_TRACKS.key("ego")
    with pytest.raises(ValueError, match="needs parameters"):
        RADAR_TRACKS.key("ego", sensor="front", extra="x")


@pytest.mark.parametrize("bad", ["a/b", "*", "", "two words"])
def test_a_parameter_must_be_one_chunk(bad):
    with pytest.raises(ValueError, match="one key chunk"):
        RADAR_TRACKS.key("ego", sensor=bad)


def test_wildcard_and_match_are_inverse():
    assert HEALTH.wildcard("ego") == "aeb/ego/health/*/*"
    assert HEALTH.wildcard("ego", service="fusion") == "aeb/ego/health/fusion/*"
    key = HEALTH.key("ego", service="fusion", instance="primary")
    assert HEALTH.match(key, "ego") == {"service": "fusion", "instance": "primary"}
    assert HEALTH.match(key, "other") is None
    assert RADAR_TRACKS.match("aeb/ego/radar/front/status", "ego") is None


def test_registry_has_every_key_of_the_design_with_rates_and_ages():
    assert set(REGISTRY) == {
        "radar_tracks", "radar_status", "camera_jpeg", "camera_depth", "camera_info",
        "fusion_targets", "fusion_brake_cmd", "brake_status", "ego_motion", "vehicle_driver",
        "vehicle_status", "health", "radar_can",
    }
    for spec in REGISTRY.values():
        if spec.msg_type is not None:
            assert spec.rate_hz and spec.max_age_s, spec.name
    assert FUSION_BRAKE_CMD.qos.express


def test_no_key_of_the_registry_waits_for_its_slowest_subscriber():
    # BLOCK would let any process that subscribes and stops reading hold the publisher's
    # whole link at the router for seconds (tests/security/test_stuck_subscriber.py)
    assert {name: spec.qos.congestion for name, spec in REGISTRY.items()
            if spec.qos.congestion is not Congestion.DROP} == {}
    assert FUSION_BRAKE_CMD.qos.priority is Priority.REAL_TIME
