"""`aeb label` as a command: the ROI file's frames found from any directory, and a port
clash said with the other command that defaults to a port, apart from aeb foxglove's."""

import http.client
import json
import os
import socket
import subprocess
import threading

import pytest

from aeb_radar_camera.tools.commands import DEFAULT_PORTS, port_in_use
from aeb_radar_camera.tools.eval.labelweb import LabelSession, make_server, pick_sample
from aeb_radar_camera.tools.eval.recording import RecordingSettings, recording_records
from aeb_radar_camera.tools.eval.records import read_records, write_records
from aeb_radar_camera.tools.eval.scoring import Scorer, default_specs
from tests.eval.fixtures import write_sim_recording
from tests.support import REPO, python_module


@pytest.fixture
def rois_written_from_their_folder(tmp_path, monkeypatch):
    """A ROI file written, as `aeb eval rois` writes it, from the folder of its recording
    named by a relative path."""
    rec = write_sim_recording(tmp_path / "drive.mcap", n_cycles=2)
    monkeypatch.chdir(tmp_path)
    records = recording_records(rec.path.relative_to(tmp_path),
                                RecordingSettings(background_per_object=0),
                                Scorer(default_specs()), {})
    assert records and not os.path.isabs(records[0].frame_ref.path)
    write_records(tmp_path / "rois" / "rois.jsonl", records)
    return tmp_path / "rois"


def test_roi_files_hold_frame_paths_that_work_from_any_directory(
        rois_written_from_their_folder, tmp_path, monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    records = read_records(rois_written_from_their_folder)
    assert all(os.path.isabs(r.frame_ref.path) for r in records)
    session = LabelSession(pick_sample(records, tmp_path / "labels.tsv", 0, [], [],
                                       (0.025,), 0), tmp_path / "labels.tsv", "t")
    server = make_server(session)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=30)
        index = json.loads(_get(conn, "/api/state")[1])["current"]["index"]
        status, body = _get(conn, f"/frame/{index}.png")
        assert status == 200 and body.startswith(b"\x89PNG"), body[:200]
    finally:
        server.shutdown()
        server.server_close()
        session.close()


def test_a_hand_written_relative_path_is_relative_to_the_roi_file(tmp_path):
    rois = tmp_path / "set" / "rois.jsonl"
    rois.parent.mkdir()
    line = json.loads(json.dumps(_minimal_record()))
    line["frame_ref"]["path"] = "../frames/0001.png"
    rois.write_text(json.dumps(line) + "\n")
    (record,) = read_records(rois)
    assert record.frame_ref.path == str(tmp_path / "frames" / "0001.png")


def _minimal_record() -> dict:
    return {"id": "a:1:front:1", "source": "kitti", "session": "a", "frame": "1", "t_ns": 0,
            "camera": "front", "image_w": 10, "image_h": 10, "roi": [0, 0, 2, 2],
            "column": [0, 0, 2, 2], "range_m": 5.0, "kind": "object",
            "frame_ref": {"kind": "image", "path": "x.png"}}


def _get(conn: http.client.HTTPConnection, path: str) -> tuple[int, bytes]:
    conn.request("GET", path)
    resp = conn.getresponse()
    return resp.status, resp.read()


def test_label_and_foxglove_default_to_different_ports_and_a_clash_names_the_other():
    assert DEFAULT_PORTS["label"] != DEFAULT_PORTS["foxglove"]
    said = port_in_use("label", "127.0.0.1", DEFAULT_PORTS["foxglove"])
    assert "aeb foxglove" in said and "--port" in said
    assert "aeb label" in port_in_use("foxglove", "127.0.0.1", DEFAULT_PORTS["label"])


def test_label_on_a_port_in_use_is_exit_2_saying_so(rois_written_from_their_folder, tmp_path):
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        port = holder.getsockname()[1]
        done = subprocess.run(python_module(
            "aeb_radar_camera.tools.cli", "label", str(rois_written_from_their_folder),
            "--include-truth",
            "--labels", str(tmp_path / "labels.tsv"), "--port", str(port)),
            capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 2, done.stderr
    assert f"127.0.0.1:{port} is in use" in done.stderr and "Traceback" not in done.stderr
