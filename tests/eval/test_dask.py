"""The same task function on a Dask cluster (a local one, on loopback) gives the same
ROIs and scores as local processes."""

import pytest

from aeb_radar_camera.tools.cli import main as aeb
from aeb_radar_camera.tools.eval.records import read_records
from tests.eval.fixtures import write_kitti, write_sim_recording

distributed = pytest.importorskip("distributed", reason="the eval extra (dask[distributed])")


def test_rois_on_a_local_dask_cluster_equal_the_local_run(tmp_path, capsys):
    recording = write_sim_recording(tmp_path / "drive.mcap").path
    kitti = write_kitti(tmp_path / "kitti", 2)
    sources = [str(recording), str(kitti), "--frames-per-task", "1", "--no-timing"]
    assert aeb(["eval", "rois", *sources, "--out", str(tmp_path / "local"), "--jobs", "1"]) == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  protocol="tcp://", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        assert aeb(["eval", "rois", *sources, "--out", str(tmp_path / "dask"),
                    "--scheduler", address]) == 0
    err = capsys.readouterr().err
    assert f"3 tasks on {address}" in err and "3/3 tasks" in err
    local = {r.id: r for r in read_records(tmp_path / "local")}
    remote = {r.id: r for r in read_records(tmp_path / "dask")}
    assert local.keys() == remote.keys() and len(local) > 10
    for key, r in local.items():
        d = remote[key]
        assert (d.roi, d.density, d.truth) == (r.roi, r.density, r.truth)
        assert {k: s.score for k, s in d.scores.items()} == {k: s.score
                                                             for k, s in r.scores.items()}
