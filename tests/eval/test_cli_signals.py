"""`aeb eval` stops on SIGTERM and SIGINT while its worker processes start or run: exit
130, no traceback, no worker left behind."""

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.eval.fixtures import write_kitti
from tests.support import REPO, wait_for


def children(pid: int) -> set[int]:
    out: set[int] = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        out |= {int(c) for c in (task / "children").read_text().split()}
    return out


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}").exists() and "Z" not in Path(
        f"/proc/{pid}/stat").read_text().split()[2]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_the_run_and_its_workers(tmp_path, sig):
    split = write_kitti(tmp_path / "kitti", n_frames=8)
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeb_radar_camera.tools.cli", "eval", "rois", str(split), "--out",
         str(tmp_path / "out"), "--jobs", "2", "--frames-per-task", "1"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stderr is not None
    line = proc.stderr.readline()
    assert "tasks on 2 local processes" in line
    workers = wait_for(lambda: children(proc.pid), 60.0, 0.01, "the worker processes")
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    wait_for(lambda: not any(alive(w) for w in workers), 30.0, 0.05, "the workers to end")
