"""A candump replay file with a garbled line: the line is skipped, counted and logged
with its number; the replay goes on with every good frame and never crashes."""

import logging
import threading

import pytest

from aeb_radar_camera.common.config.radar import CanSettings, Pace, RadarSettings, ReplaySettings
from aeb_radar_camera.services.radar.ports import ReplayPort
from aeb_radar_camera.services.radar.shell import RadarShell
from tests.can_support import RECORDING, RECORDING_CYCLES
from tests.radar.test_shell import Output

GOOD = "(1782308579.164027) can1 60B#384F04028020019C\n"
CORRUPT_LINES = {
    "garbled_hex": b"(1782308579.164027) can1 60B#38ZZ04028020019C\n",
    "garbled_id": b"(1782308579.164027) can1 6G0B#384F04028020019C\n",
    "garbled_timestamp": b"(1782308579.16x027) can1 60B#384F04028020019C\n",
    "truncated_timestamp": b"(1782308\n",
    "missing_hash": b"(1782308579.164027) can1 60B384F04028020019C\n",
    "binary_junk": b"\x00\xff\xfe\x81garbage\x9c\n",
    "extra_field": b"(1782308579.164027) can1 60B#384F04028020019C extra\n",
    "odd_fd_flags": b"(1782308579.164027) can1 60B##\n",
}
AT_LINE = 500   # well inside the recording's cycles


def corrupted(tmp_path, line: bytes) -> str:
    lines = RECORDING.read_bytes().splitlines(keepends=True)
    path = tmp_path / "corrupt.log"
    path.write_bytes(b"".join(lines[:AT_LINE - 1]) + line + b"".join(lines[AT_LINE - 1:]))
    return str(path)


@pytest.mark.parametrize("kind", sorted(CORRUPT_LINES))
def test_a_bad_line_is_skipped_counted_and_logged_with_its_number(tmp_path, kind, caplog):
    caplog.set_level(logging.WARNING, logger="radar.replay")
    port = ReplayPort(corrupted(tmp_path, CORRUPT_LINES[kind]), Pace.FAST)
    frames = list(iter(lambda: port.recv(0), None))
    assert port.ended
    assert len(frames) == len(RECORDING.read_bytes().splitlines())
    assert port.line_errors.snapshot() == {"bad_line": 1}
    logged = [r.getMessage() for r in caplog.records]
    assert len(logged) == 1 and f"line={AT_LINE}" in logged[0], logged


def test_bad_lines_are_rate_limited_in_the_log_but_all_counted(tmp_path, caplog):
    caplog.set_level(logging.WARNING, logger="radar.replay")
    path = tmp_path / "junk.log"
    path.write_bytes(GOOD.encode() + b"not a frame\n" * 1000 + GOOD.encode())
    port = ReplayPort(str(path), Pace.FAST)
    assert len(list(iter(lambda: port.recv(0), None))) == 2
    assert port.line_errors.get("bad_line") == 1000
    assert len(caplog.records) == 1


def test_the_service_replays_a_corrupted_file_to_the_end_and_reports_the_bad_line(tmp_path):
    s = RadarSettings(can=CanSettings(interface="replay"),
                      replay=ReplaySettings(file=corrupted(tmp_path, CORRUPT_LINES["binary_junk"]),
                                            pace=Pace.FAST, exit_at_end=True))
    out = Output()
    assert RadarShell(s, out).run(threading.Event()) == 0
    final = out.last_status()
    assert final.cycles_total == RECORDING_CYCLES
    assert final.rejected == {"bus:replay_bad_line": 1}


def test_a_looping_replay_counts_the_bad_line_on_every_pass(tmp_path):
    path = tmp_path / "loop.log"
    path.write_bytes(GOOD.encode() + CORRUPT_LINES["missing_hash"] + GOOD.encode())
    port = ReplayPort(str(path), Pace.FAST, loop=True)
    frames = [port.recv(0) for _ in range(6)]
    assert all(f is not None for f in frames) and port.loops >= 2
    assert port.line_errors.get("bad_line") == port.loops + 1
    port.shutdown()


BAD_STAMPS = {
    "infinite": b"(inf) can1 60B#384F04028020019C\n",
    "not_a_number": b"(nan) can1 60B#384F04028020019C\n",
    "a_million_seconds_ahead": b"(1782308579.164027) can1 60B#384F04028020019C\n",
    "an_hour_back": b"(1782304979.164027) can1 60B#384F04028020019C\n",
}


def first_cycles(tmp_path, line: bytes, seconds: float = 2.0) -> tuple[str, int]:
    """The recording's first `seconds` with `line` in the middle (its stamp made to
    differ from its neighbours' as the key says); the number of frames in it."""
    lines = RECORDING.read_bytes().splitlines(keepends=True)
    t0 = float(lines[0].split(b")")[0][1:])
    kept = [ln for ln in lines if float(ln.split(b")")[0][1:]) - t0 < seconds]
    if line.startswith(b"(1782308579"):      # re-stamped relative to the recording
        shift = 1e6 if line == BAD_STAMPS["a_million_seconds_ahead"] else -3600.0
        line = b"(%.6f" % (t0 + seconds / 2 + shift) + line[line.index(b")"):]
    path = tmp_path / "stamps.log"
    middle = len(kept) // 2
    path.write_bytes(b"".join(kept[:middle]) + line + b"".join(kept[middle:]))
    return str(path), len(kept)


@pytest.mark.parametrize("kind", sorted(BAD_STAMPS))
def test_a_bad_stamp_never_stalls_a_paced_replay(tmp_path, kind, caplog):
    caplog.set_level(logging.WARNING, logger="radar.replay")
    now = [0.0]

    def sleep(s: float) -> None:   # a fake clock: the test sees a wait as time passing
        now[0] += s

    path, n = first_cycles(tmp_path, BAD_STAMPS[kind])
    port = ReplayPort(path, Pace.REALTIME, clock=lambda: now[0], sleep=sleep)
    frames = []
    for _ in range(100 * n):
        if port.ended:
            break
        if (msg := port.recv(0.1)) is not None:
            frames.append(msg)
    assert port.ended, f"stalled after {len(frames)} of {n} frames"
    stamps = [f.timestamp for f in frames]
    assert stamps == sorted(stamps) and stamps[-1] - stamps[0] < 5.0
    if kind in ("infinite", "not_a_number"):
        assert len(frames) == n and port.line_errors.snapshot() == {"bad_stamp": 1}
    else:   # the jump frame and the rest kept, re-based once there and once back
        assert len(frames) == n + 1 and port.line_errors.snapshot() == {"stamp_jump": 2}
    assert caplog.records, "a bad stamp is logged"


def test_the_service_replays_past_an_infinite_stamp_in_real_time(tmp_path):
    path, _ = first_cycles(tmp_path, BAD_STAMPS["infinite"])
    s = RadarSettings(can=CanSettings(interface="replay"),
                      replay=ReplaySettings(file=path, pace=Pace.REALTIME, exit_at_end=True))
    out, stop, result = Output(), threading.Event(), []
    runner = threading.Thread(target=lambda: result.append(RadarShell(s, out).run(stop)))
    runner.start()
    runner.join(timeout=60.0)     # 2 s of recording; the stall was forever
    stop.set()
    runner.join()
    assert result == [0]
    final = out.last_status()
    assert final.cycles_total >= 20
    assert final.rejected == {"bus:replay_bad_stamp": 1}
