"""Rate contracts: a key whose registry rate is a minimum ("at least 10 Hz") is on rate
at any higher rate, and off rate below it; a fixed-rate key is off rate both ways."""

import pytest

from aeb_radar_camera.common.freshness import Freshness
from aeb_radar_camera.common.keys import BRAKE_STATUS, RADAR_STATUS, RADAR_TRACKS

S = 1_000_000_000


def health_at(spec, rate_hz: float):
    f = Freshness.from_spec(spec, window_s=2.0)
    period = round(S / rate_hz)
    now = 0
    for i in range(int(3 * rate_hz)):
        now = i * period
        f.observe(now)
    return f.health(now)


@pytest.mark.parametrize("rate_hz", [10.0, 13.3, 40.0])
def test_brake_status_at_or_above_its_minimum_is_on_rate(rate_hz):
    h = health_at(BRAKE_STATUS, rate_hz)
    assert h.alive and h.on_rate, h


def test_brake_status_below_its_minimum_is_off_rate():
    h = health_at(BRAKE_STATUS, 5.0)
    assert not h.on_rate


def test_radar_status_on_every_change_above_1_hz_is_on_rate():
    assert health_at(RADAR_STATUS, 3.0).on_rate


@pytest.mark.parametrize("rate_hz", [6.0, 30.0])
def test_a_fixed_rate_key_far_from_its_rate_is_off_rate(rate_hz):
    assert not RADAR_TRACKS.rate_is_minimum
    assert not health_at(RADAR_TRACKS, rate_hz).on_rate


def test_a_fixed_rate_key_at_its_rate_is_on_rate():
    assert health_at(RADAR_TRACKS, 1 / 0.075).on_rate
