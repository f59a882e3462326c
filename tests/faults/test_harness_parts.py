"""The harness's own parts, without a stack: the CAN gate, the loopback relay that
stands in for a cut link, the mutations, and the fault table."""

import random
import socket
import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.tools.faults.catalogue import Outcome, stream_gaps
from aeb_radar_camera.tools.faults.harness import Record, RunInfo
from aeb_radar_camera.tools.faults.links import CanGate, RelayLink
from aeb_radar_camera.tools.faults.mutate import mutate_bytes, mutate_msgpack, mutate_tree
from aeb_radar_camera.tools.faults.observe import Observer, Seen, Stream
from aeb_radar_camera.tools.faults.report import markdown, rows, write
from aeb_radar_camera.tools.faults.robust import run_dir


class ListSink:
    def __init__(self) -> None:
        self.frames: list[int] = []

    def send(self, frames):
        self.frames += list(frames)


def test_can_gate_passes_then_cuts_a_cycle_after_n_frames_then_restores():
    sink = ListSink()
    gate = CanGate(sink)
    gate.send([1, 2, 3])
    gate.silence(after_frames=2)
    gate.send([4, 5, 6])        # a cycle cut after its second frame
    gate.send([7])
    assert sink.frames == [1, 2, 3, 4, 5]
    assert gate.dropped == 2
    gate.restore()
    gate.send([8])
    assert sink.frames[-1] == 8


def _echo_server() -> tuple[socket.socket, int]:
    srv = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            threading.Thread(target=_echo, args=(conn,), daemon=True).start()

    threading.Thread(target=serve, daemon=True).start()
    return srv, srv.getsockname()[1]


def _echo(conn: socket.socket) -> None:
    with conn:
        while data := conn.recv(1024):
            conn.sendall(data)


def test_relay_forwards_until_cut_refuses_while_cut_and_forwards_after_restore():
    srv, port = _echo_server()
    relay = RelayLink(port)
    try:
        with socket.create_connection(("127.0.0.1", relay.port), timeout=5) as c:
            c.sendall(b"ping")
            assert c.recv(16) == b"ping"
            relay.cut()
            c.settimeout(5)
            assert c.recv(16) == b""          # the relayed connection is gone
        with socket.create_connection(("127.0.0.1", relay.port), timeout=5) as c:
            c.settimeout(5)
            assert c.recv(16) == b""          # refused while cut
        relay.restore()
        with socket.create_connection(("127.0.0.1", relay.port), timeout=5) as c:
            c.sendall(b"back")
            assert c.recv(16) == b"back"
    finally:
        relay.remove()
        srv.close()


def test_mutations_are_reproducible_and_bounded():
    seed = bytes(range(64))
    a = [mutate_bytes(random.Random(i), seed) for i in range(200)]
    b = [mutate_bytes(random.Random(i), seed) for i in range(200)]
    assert a == b
    assert sum(x != seed for x in a) > 150
    assert max(len(x) for x in a) <= 2 * len(seed) + 64
    tree = {"a": {"b": 1.0, "c": [1, 2]}, "d": "x"}
    assert sum(mutate_tree(random.Random(i), tree) != tree for i in range(100)) > 80
    assert tree == {"a": {"b": 1.0, "c": [1, 2]}, "d": "x"}     # the original untouched
    payload = b"\x82\xa1a\x01\xa1b\xa1x"
    assert any(mutate_msgpack(random.Random(i), payload) != payload for i in range(20))


def test_table_counts_injections_bounds_and_losses(tmp_path):
    rec = Record("SIGKILL fusion", "brake FAILSAFE")
    rec.outcomes = [Outcome(True, 200.5), Outcome(True, 201.5), Outcome(False, 300.0, "late"),
                    Outcome(False, None, "no FAILSAFE line", lost=1)]
    rec.recover_s = [1.0, 2.0, 3.0]
    rec.unrecovered = 1
    skipped = Record("link cut", "brake FAILSAFE", skipped="no netns")
    info = RunInfo("quick", 1, 1, 12.0, "loopback relay")
    table = rows([rec, skipped])
    assert table[0]["injections"] == 4 and table[0]["within_bound"] == 2
    assert table[0]["p50_ms"] == 201.5 and table[0]["max_ms"] == 300.0
    assert table[0]["lost"] == 1 and table[0]["recover_p50_s"] == 2.0
    text = markdown(table, info)
    assert "| SIGKILL fusion | brake FAILSAFE | 4 | 2 | - | 201.5 | 300.0 |" in text
    assert "skipped: no netns" in text and "late" in text
    md, js, png = write(tmp_path, [rec, skipped], info)
    assert md.is_file() and js.is_file() and png is not None and png.stat().st_size > 1000


def test_tables_of_two_runs_combine_into_one(tmp_path):
    from aeb_radar_camera.tools.faults.report import combine
    a, b = Record("SIGKILL radar", "FAILSAFE"), Record("frozen camera", "unavailable")
    a.outcomes, a.recover_s = [Outcome(True, 200.0, bound_ms=260.0)] * 3, [1.0] * 3
    b.skipped = "not in this run"
    write(tmp_path / "one", [a, b], RunInfo("soak", 3, 3, 60.0, "netns"))
    a2, b2 = Record("SIGKILL radar", "FAILSAFE"), Record("frozen camera", "unavailable")
    a2.skipped = "not in this run"
    b2.outcomes = [Outcome(True, 900.0, bound_ms=2000.0), Outcome(False, None, "none")]
    write(tmp_path / "two", [a2, b2], RunInfo("soak", 2, 2, 30.0, "netns"))
    records, info = combine([tmp_path / "one" / "faults.json", tmp_path / "two" / "faults.json"])
    by = {r.fault: r for r in records}
    assert len(by["SIGKILL radar"].outcomes) == 3 and not by["SIGKILL radar"].skipped
    assert [o.ok for o in by["frozen camera"].outcomes] == [True, False]
    assert info.seconds == 90.0 and len(info.runs) == 2
    assert "2 runs" in markdown(rows(records), info)


def test_the_run_folder_is_absolute_when_out_is_relative(tmp_path, monkeypatch):
    # the services a fault starts run in that folder on files named by it: a relative
    # `--out` once made every "bad config strings" start read a path that did not exist
    monkeypatch.chdir(tmp_path)
    ctx = cast(Any, SimpleNamespace(loop=SimpleNamespace(log_path=Path("out/x/stack.log"))))
    folder = run_dir(ctx)
    assert folder.is_absolute()
    assert folder == tmp_path / "out" / "x" / "run"


def test_a_helper_process_that_ignores_sigterm_is_killed_not_left_to_end_the_run():
    import subprocess
    import sys

    from aeb_radar_camera.tools.faults.security import end_process
    code = ("import signal, sys, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); "
            "print('ready', flush=True); time.sleep(60)")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    assert end_process(proc, grace_s=0.5) == -9
    assert proc.poll() == -9


def test_a_failsafe_during_a_camera_fault_says_which_stream_stopped():
    ms = 1_000_000
    obs = Observer.__new__(Observer)
    obs.tracks, obs.targets, obs.commands = Stream(), Stream(), Stream()
    # radar every 70 ms throughout; fusion receives and commands each, but for a 280 ms
    # stall after the cycle at 700 ms (the three cycles in it decided late, together).
    def msg(**fields: Any) -> Any:      # the fields stream_gaps reads, as a message's
        return SimpleNamespace(**fields)

    for t in range(0, 1400, 70):
        stamp = t * ms + wall_ns() - mono_ns()
        obs.tracks.add(Seen(0, msg(header=msg(pub_mono_ns=t * ms, stamp_ns=stamp))))
        rx = t if not 700 < t < 980 else 980
        pub = rx + 2
        obs.targets.add(Seen(0, msg(header=msg(pub_mono_ns=pub * ms),
                                    processing_ns=(pub - rx) * ms)))
        obs.commands.add(Seen(0, msg(header=msg(pub_mono_ns=pub * ms))))
    failsafe = SimpleNamespace(header=SimpleNamespace(pub_mono_ns=910 * ms),
                               last_cmd_rx_mono_ns=703 * ms)
    sent = [(t * ms - 3 * ms, t * ms - 2 * ms) for t in range(0, 1400, 70)]
    text = stream_gaps(obs, 0, cast(Any, failsafe), sent)
    assert "simulated radar wrote gap 70 ms" in text and "longest cycle write 1 ms" in text
    assert "radar received gap 70 ms" in text and "radar published gap 70 ms" in text
    # the stall still open at the FAILSAFE: from the last cycle before it
    assert "fusion received gap 210 ms at -210 ms" in text
    assert "fusion commanded gap 208 ms at -208 ms" in text
    assert "0 commands published after the brake's last receipt" in text


def test_the_harness_measures_its_own_garbage_collections_and_reports_the_longest(tmp_path):
    import gc

    from aeb_radar_camera.tools.faults.gc_pauses import GcPauses

    pauses = GcPauses().start()
    kept = [[i] for i in range(200_000)]       # tracked: a full collection walks them
    gc.collect()
    pauses.stop()
    assert pauses.collections >= 1 and pauses.max_ms > 0.0
    counted = pauses.collections
    gc.collect()
    assert pauses.collections == counted          # stopped: no longer counting
    del kept
    info = RunInfo("soak", 1, 1, 12.0, "loopback relay")
    info.gc_pause_max_ms = pauses.max_ms
    text = markdown(rows([]), info)
    assert f"the harness's longest garbage collection {pauses.max_ms:.0f} ms" in text
