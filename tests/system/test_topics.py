"""`aeb echo` and `aeb hz` against a live bus: decoded messages of any key (found by the
samples' encoding or by their key), and rates with min / max / std of the period."""

import json
import math
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import msgspec
import pytest

from aeb_radar_camera.common.keys import CAMERA_JPEG, FUSION_BRAKE_CMD, RADAR_TRACKS
from aeb_radar_camera.common.messages import BrakeCommand, RadarTracks, encode
from aeb_radar_camera.tools.topics.catalog import Catalog
from aeb_radar_camera.tools.topics.echo import decode_sample, json_line, table_row
from aeb_radar_camera.tools.topics.rates import PeriodStats
from tests.messages_support import example
from tests.support import open_bus

MS = 1_000_000


# -- pure parts ---------------------------------------------------------------------------

def test_period_stats_are_mean_rate_min_max_and_std_over_the_window():
    stats = PeriodStats(window=4)
    t = 0
    for period in (70, 80, 70, 80, 70, 80):      # only the last four periods count
        stats.add(t)
        t += period * MS
    stats.add(t)
    r = stats.report()
    assert (r.count, r.window) == (7, 4)
    assert r.rate_hz == pytest.approx(1000 / 75)
    assert (r.min_s, r.max_s) == (0.070, 0.080)
    assert r.std_s == pytest.approx(0.005)


def test_period_stats_before_two_messages_and_with_times_going_backwards():
    stats = PeriodStats()
    assert stats.report().rate_hz == 0.0 and math.isnan(stats.report().std_s)
    for t in (0, 100, 50, 200):
        stats.add(t * MS)
    r = stats.report()
    assert r.backwards == 1 and r.window == 2 and r.min_s == r.max_s == 0.1


@pytest.mark.parametrize(("typed", "expected"), [
    ("radar_tracks", "aeb/ego/radar/*/tracks"),
    ("radar/front/tracks", "aeb/ego/radar/front/tracks"),
    ("fusion/*/brake_cmd", "aeb/ego/fusion/*/brake_cmd"),
    ("**", "aeb/ego/**"),
    ("aeb/car2/brake/status", "aeb/car2/brake/status"),
])
def test_what_a_user_types_becomes_a_key_expression(typed, expected):
    assert Catalog("ego").expression(typed) == expected


def test_the_type_comes_from_the_encoding_else_from_the_key():
    cat = Catalog("ego")
    assert cat.type_of("aeb/ego/anything", "application/msgpack;aeb.BrakeCommand") \
        is BrakeCommand
    assert cat.type_of("aeb/ego/radar/front/tracks", "zenoh/bytes") is RadarTracks
    assert cat.type_of("aeb/ego/unknown", "zenoh/bytes") is None


def test_json_lines_and_table_rows_summarise_bytes():
    cat = Catalog("ego")
    frame = example(CAMERA_JPEG.msg_type)
    sample = (encode(frame), "aeb/ego/camera/front/jpeg", "", 5)
    line = json.loads(json_line(decode_sample(cat, sample), full_bytes=False))
    assert line["msg"]["jpeg"] == {"bytes": len(frame.jpeg)} and line["type"] == \
        "CompressedFrame"
    assert "jpeg={bytes 2}" in table_row(cat, decode_sample(cat, sample))
    full = json.loads(json_line(decode_sample(cat, sample), full_bytes=True))
    assert isinstance(full["msg"]["jpeg"], str)                    # base64
    bad = decode_sample(cat, (b"\x00junk", "aeb/ego/camera/front/jpeg", "", 5))
    assert bad.msg is None and "UNDECODABLE 5 B" in table_row(cat, bad)


# -- against a router ---------------------------------------------------------------------

def aeb(*args: str) -> list[str]:
    return [sys.executable, "-m", "aeb_radar_camera.tools.cli", *args]


@contextmanager
def publishing(router: str, put) -> Iterator[threading.Event]:
    """Call `put(bus, i)` about every 5 ms on a thread until the block ends (a tool's
    subscription must have propagated before it sees anything; pacing, not a wait)."""
    stop = threading.Event()

    def run() -> None:
        with open_bus(router, source="pub") as bus:
            i = 0
            while not stop.wait(0.005):
                put(bus, i)
                i += 1

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield stop
    finally:
        stop.set()
        thread.join(10)


def lines_until(proc: subprocess.Popen[str], done, timeout_s: float = 60.0) -> list[str]:
    """stdout lines of `proc` until `done(lines)`, or its end."""
    got: list[str] = []
    timer = threading.Timer(timeout_s, proc.kill)
    timer.start()
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            got.append(line.rstrip("\n"))
            if done(got):
                break
    finally:
        timer.cancel()
    return got


def command(seq: int) -> BrakeCommand:
    return msgspec.structs.replace(example(BrakeCommand), header=msgspec.structs.replace(
        example(BrakeCommand).header, seq=seq))


def test_echo_prints_decoded_messages_and_undecodable_samples(router):
    def put(bus, i):
        if i % 2:
            bus.session.put(bus.key(FUSION_BRAKE_CMD, instance="primary"), b"\x00junk")
        else:
            bus.publisher(FUSION_BRAKE_CMD, instance="primary").put(command(i))

    with publishing(router, put):
        proc = subprocess.run(aeb("echo", "fusion/primary/brake_cmd", "--count", "6",
                                  "--connect", router), capture_output=True, text=True,
                              timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = [json.loads(ln) for ln in proc.stdout.splitlines()]
    assert len(lines) == 6
    good = [ln for ln in lines if "msg" in ln]
    bad = [ln for ln in lines if "error" in ln]
    assert good and bad
    assert {ln["type"] for ln in lines} == {"BrakeCommand"}
    assert all(ln["msg"]["header"]["seq"] % 2 == 0 for ln in good)
    assert all(ln["size"] == 5 for ln in bad)
    assert "undecodable" in proc.stderr


def test_echo_decodes_a_key_outside_the_registry_by_its_encoding(router):
    with publishing(router, lambda bus, i: bus.session.put(
            "aeb/ego/bench/relay", encode(command(i)),
            encoding="application/msgpack;aeb.BrakeCommand")):
        proc = subprocess.run(aeb("echo", "bench/relay", "--count", "1", "--table",
                                  "--connect", router), capture_output=True, text=True,
                              timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "bench/relay" in proc.stdout and "decision=NONE" in proc.stdout


def test_echo_with_nothing_on_the_key_exits_1_after_its_timeout(router):
    proc = subprocess.run(aeb("echo", "radar/nowhere/tracks", "--timeout", "1",
                              "--connect", router), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 1 and "nothing on aeb/ego/radar/nowhere/tracks" in proc.stderr


def test_hz_reports_rate_and_period_statistics_of_the_stamps(router):
    # stamps 70 and 80 ms apart in turn: 13.33 Hz, min 70, max 80, std 5 ms, whatever
    # the publishing pace or the network's jitter
    tracks = example(RADAR_TRACKS.msg_type)

    def put(bus, i):
        stamp = 1_800_000_000 * 10**9 + (i // 2) * 150 * MS + (70 * MS if i % 2 else 0)
        header = msgspec.structs.replace(tracks.header, seq=i, stamp_ns=stamp)
        bus.publisher(RADAR_TRACKS, sensor="front").put(
            msgspec.structs.replace(tracks, header=header))

    with publishing(router, put):
        proc = subprocess.Popen(aeb("hz", "radar/front/tracks", "--clock", "stamp", "--json",
                                    "--interval", "0.5", "--window", "20",
                                    "--connect", router), stdout=subprocess.PIPE, text=True)
        try:
            lines = lines_until(proc, lambda got: any(
                (v := json.loads(ln)["keys"].get("aeb/ego/radar/front/tracks"))
                and v["window"] == 20 for ln in got))
        finally:
            proc.terminate()
            proc.wait(30)
    report = json.loads(lines[-1])["keys"]["aeb/ego/radar/front/tracks"]
    assert report["rate_hz"] == pytest.approx(1000 / 75, rel=1e-6)
    assert (report["min_s"], report["max_s"]) == pytest.approx((0.070, 0.080))
    assert report["std_s"] == pytest.approx(0.005, rel=1e-6)


def test_hz_on_every_key_lists_each_with_its_nominal_rate(router):
    def put(bus, i):
        bus.publisher(FUSION_BRAKE_CMD, instance="primary").put(command(i))
        bus.publisher(RADAR_TRACKS, sensor="front").put(example(RADAR_TRACKS.msg_type))

    with publishing(router, put):
        proc = subprocess.Popen(aeb("hz", "**", "--interval", "0.5", "--connect", router),
                                stdout=subprocess.PIPE, text=True)
        try:
            lines = lines_until(proc, lambda got: sum(
                ln.startswith(("fusion/primary/brake_cmd", "radar/front/tracks"))
                for ln in got[-4:]) == 2)
        finally:
            proc.terminate()
            proc.wait(30)
    header = next(ln for ln in lines if ln.startswith("key"))
    assert header.split() == ["key", "rate_hz", "nominal", "min_ms", "max_ms", "std_ms",
                              "window", "msgs"]
    row = next(ln for ln in reversed(lines) if ln.startswith("fusion/primary/brake_cmd"))
    assert row.split()[2] == "13.33"          # the registry's nominal rate
    assert float(row.split()[1]) > 0


# -- a misspelt key, `aeb list`, `aeb nodes` ------------------------------------------------


def test_a_misspelt_key_is_said_with_the_registry_names_nearest_to_it():
    catalog = Catalog("ego")
    assert not catalog.known(catalog.expression("radar/front/trakcs"))
    assert catalog.known(catalog.expression("fusion/*/brake_cmd"))
    assert catalog.known(catalog.expression("**"))
    assert catalog.suggest("radar/front/trakcs")[0] == "radar/front/tracks (radar_tracks)"
    assert catalog.suggest("radar_trakcs")[0] == "radar_tracks"
    assert catalog.suggest("zzz") == []


def test_echo_on_a_misspelt_key_says_it_and_that_nothing_publishes_it(router):
    proc = subprocess.run(aeb("echo", "radar/front/trakcs", "--timeout", "4",
                              "--connect", router), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 1
    assert "aeb/ego/radar/front/trakcs is no key of the registry; did you mean " \
           "radar/front/tracks (radar_tracks)" in proc.stderr
    assert "nothing on aeb/ego/radar/front/trakcs in 3 s: no publisher yet" in proc.stderr


def test_list_names_each_key_heard_with_its_type_publisher_and_rate(router):
    def put(bus, i):
        bus.publisher(FUSION_BRAKE_CMD, instance="primary").put(command(i))
        if i % 4 == 0:
            bus.publisher(RADAR_TRACKS, sensor="front").put(example(RadarTracks))

    with publishing(router, put):
        proc = subprocess.run(aeb("list", "--json", "--all", "--connect", router),
                              capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    rows = {r["key"]: r for r in json.loads(proc.stdout)["keys"]}
    cmd = rows["fusion/primary/brake_cmd"]
    assert cmd["type"] == "BrakeCommand" and cmd["messages"] > 10 and cmd["rate_hz"] > 20
    assert cmd["publishers"] == [example(BrakeCommand).header.source]
    assert rows["radar/front/tracks"]["rate_hz"] < cmd["rate_hz"]
    # --all: a key of the registry nobody published, said as such
    assert rows["brake/status"]["messages"] == 0 and rows["brake/status"]["publishers"] == []


def test_list_on_a_silent_bus_exits_1(router):
    proc = subprocess.run(aeb("list", "--duration", "0.5", "--connect", router),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and "0 key(s) heard" in proc.stdout


def test_nodes_lists_the_liveliness_tokens_and_their_keys(router):
    with open_bus(router, source="node") as bus:
        radar = bus.declare_health("radar", "front")
        fusion = bus.declare_health("fusion", "primary")

        def put(b, i):
            b.publisher(RADAR_TRACKS, sensor="front").put(msgspec.structs.replace(
                example(RadarTracks), header=msgspec.structs.replace(
                    example(RadarTracks).header, source="radar/front")))
            b.session.put("aeb/ego/sim/world", b"\x00", encoding="application/msgpack")

        with publishing(router, put):
            proc = subprocess.run(aeb("nodes", "--keys", "--json", "--connect", router),
                                  capture_output=True, text=True, timeout=120)
        radar.undeclare()
        after = subprocess.run(aeb("nodes", "--connect", router), capture_output=True,
                               text=True, timeout=120)
        fusion.undeclare()
    assert proc.returncode == 0, proc.stderr
    said = json.loads(proc.stdout)
    assert said["nodes"] == ["fusion/primary", "radar/front"]
    assert said["keys"]["radar/front"] == ["radar/front/tracks"]
    assert said["keys"]["fusion/primary"] == []
    assert after.stdout.split() == ["fusion/primary"]
