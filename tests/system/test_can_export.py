"""`aeb can-export`: the real ARS408 recording decoded to CSV with the shipped DBC by
cantools, value for value what the radar service's own decoder reads."""

import csv
import io

import can
import pytest

from aeb_radar_camera.common.resources import ARS408_RECORDING
from aeb_radar_camera.services.radar.ars408 import RadarFrameError, decode_frame
from aeb_radar_camera.tools.can_export import LONG_HEAD, main
from tests.can_support import RECORDING_FRAMES, recording_messages
from tests.extras_support import run_without
from tests.support import REPO


def export(capsys, *args: str) -> tuple[list[dict[str, str]], str]:
    assert main([*args]) == 0
    out, err = capsys.readouterr()
    return list(csv.DictReader(io.StringIO(out))), err


def test_every_frame_of_the_recording_matches_the_services_decoder(capsys):
    rows, err = export(capsys, str(ARS408_RECORDING))
    assert len(rows) == RECORDING_FRAMES
    assert f"{RECORDING_FRAMES} frames exported" in err and "skipped" not in err
    compared = 0
    for row, frame in zip(rows, recording_messages(), strict=True):
        spec, sensor_id, record = decode_frame(frame.arbitration_id, frame.data)
        assert (row["message"], sensor_id) == (spec.dbc_name, 0)
        assert float(row["time_s"]) == pytest.approx(frame.timestamp, abs=1e-6)
        for sig in spec.signals:
            assert float(row[f"{spec.dbc_name}.{sig.dbc_name}"]) == pytest.approx(
                getattr(record, sig.attr), abs=1e-9), (row, sig)
            compared += 1
        others = [k for k, v in row.items() if v and "." in k
                  and not k.startswith(spec.dbc_name + ".")]
        assert not others
    assert compared > 50_000


def test_long_format_one_row_per_signal_with_units(capsys):
    rows, _ = export(capsys, str(ARS408_RECORDING), "--format", "long", "--only",
                     "Obj_1_General", "--relative-time")
    n_general = sum(m.arbitration_id == 0x60B for m in recording_messages())
    assert len(rows) == 7 * n_general
    assert list(rows[0]) == LONG_HEAD
    assert float(rows[0]["time_s"]) == 0.0
    units = {r["signal"]: r["unit"] for r in rows}
    assert units["Obj_DistLong"] == "m" and units["Obj_RCS"] == "dBsm"


def write_log(path, frames: list[can.Message]) -> str:
    with can.Logger(str(path)) as log:
        for f in frames:
            log.on_message_received(f)
    return str(path)


def test_another_sensor_id_and_what_cannot_be_exported_is_counted(tmp_path, capsys):
    general = next(m for m in recording_messages() if m.arbitration_id == 0x60B)
    shifted = can.Message(timestamp=1.0, arbitration_id=0x61B, data=general.data,
                          is_extended_id=False, channel="can0")
    short = can.Message(timestamp=2.0, arbitration_id=0x61B, data=general.data[:3],
                        is_extended_id=False, channel="can0")
    unknown = can.Message(timestamp=3.0, arbitration_id=0x123, data=b"\x00",
                          is_extended_id=False, channel="can0")
    log = write_log(tmp_path / "radar1.log", [shifted, short, unknown])
    rows, err = export(capsys, log, "--sensor-id", "1")
    assert len(rows) == 1 and rows[0]["can_id"] == "0x61B"
    _, _, record = decode_frame(0x60B, general.data)
    assert float(rows[0]["Obj_1_General.Obj_DistLong"]) == pytest.approx(record.dist_long_m)
    assert "1 Obj_1_General:" in err and "1 id 0x123 not in the DBC" in err
    with pytest.raises(RadarFrameError):
        decode_frame(0x60B, short.data)           # the service rejects it too
    _, err = export(capsys, log)                   # as SensorID 0: none of them is known
    assert "0 frames exported" in err and "2 id 0x61B not in the DBC" in err


@pytest.mark.parametrize(("args", "said"), [
    (["missing.log"], "missing.log: no such file"),
    ([str(ARS408_RECORDING), "--dbc", "missing.dbc"], "cannot read the DBC"),
    ([str(ARS408_RECORDING), "--only", "Obj_9_Nothing"], "no such message"),
    ([str(ARS408_RECORDING), "--dbc", "README.md"], "README.md: not a CAN database"),
    ([str(ARS408_RECORDING), "--dbc", "deploy/radar.toml"], "radar.toml: not a CAN database"),
])
def test_bad_input_is_exit_2_naming_it(capsys, monkeypatch, args, said):
    monkeypatch.chdir(REPO)
    assert main(args) == 2
    assert said in capsys.readouterr().err


def test_without_cantools_the_extra_is_named():
    r = run_without({"cantools"}, "import sys\nfrom aeb_radar_camera.tools.cli import main\n"
                                  f"sys.exit(main(['can-export', {str(ARS408_RECORDING)!r}]))")
    assert r.returncode == 2 and "pip install 'aeb-radar-camera[dbc]'" in r.stderr
