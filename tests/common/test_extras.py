"""Extras per role: the base install runs the brake and the router, and each role's
extra (pyproject.toml) is enough for its commands. Each check runs in a fresh
interpreter in which the optional packages outside the role cannot be imported."""

import json
import tomllib

import pytest

from aeb_radar_camera.tools.commands import COMMANDS
from tests.extras_support import run_without
from tests.support import REPO

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
# distribution -> the module it provides
MODULE_OF = {"python-can": "can", "numpy": "numpy", "opencv-python-headless": "cv2",
             "simplejpeg": "simplejpeg", "matplotlib": "matplotlib", "cantools": "cantools",
             "pyrealsense2": "pyrealsense2", "zstandard": "zstandard", "mcap": "mcap",
             "foxglove-sdk": "foxglove", "dask[distributed]": "dask"}
OPTIONAL = set(MODULE_OF.values())

def _dist(requirement: str) -> str:
    for sep in "<>=;! ":
        requirement = requirement.split(sep)[0]
    return requirement if requirement in MODULE_OF else requirement.split("[")[0]


def extra_modules(extra: str) -> set[str]:
    """The optional modules an extra installs, following self-references."""
    out: set[str] = set()
    for req in PYPROJECT["project"]["optional-dependencies"][extra]:
        if req.startswith(PYPROJECT["project"]["name"] + "["):
            for inner in req.split("[", 1)[1].rstrip("]").split(","):
                out |= extra_modules(inner.strip())
        elif _dist(req) in MODULE_OF:
            out.add(MODULE_OF[_dist(req)])
    return out


def test_no_optional_package_is_a_base_dependency():
    base = {_dist(r) for r in PYPROJECT["project"]["dependencies"]}
    assert not base & set(MODULE_OF)


def test_the_blocker_blocks():
    # the tests below mean something only if a blocked module really cannot be imported
    r = run_without({"numpy"}, "import numpy")
    assert r.returncode != 0 and "No module named 'numpy'" in r.stderr


@pytest.mark.parametrize("command", ["brake", "router", "up", "sim-actuator"])
def test_the_base_install_runs(command):
    r = run_without(OPTIONAL, "import sys\nfrom aeb_radar_camera.tools.cli import main\n"
                              f"sys.exit(main([{command!r}, '--help']))")
    assert r.returncode == 0, r.stderr
    assert "usage: aeb" in r.stdout


@pytest.mark.parametrize(("extra", "modules"), [
    ("radar", ["aeb_radar_camera.services.radar.main"]),
    ("camera", ["aeb_radar_camera.services.camera.main", "aeb_radar_camera.tools.sim.moving_box"]),
    ("fusion", ["aeb_radar_camera.services.fusion.main", "aeb_radar_camera.tools.calib.check"]),
    ("monitor", ["aeb_radar_camera.tools.monitor.main"]),
    ("vehicle", ["aeb_radar_camera.services.vehicle.main"]),
    ("demo", ["aeb_radar_camera.tools.demo", "benchmarks.suite",
              "aeb_radar_camera.tools.sim.camera_source"]),
    ("dbc", ["aeb_radar_camera.tools.can_export", "cantools", "can"]),
    # what the recording commands import once their arguments are read
    ("record", ["aeb_radar_camera.tools.recording.record",
                "aeb_radar_camera.tools.recording.recorder",
                "aeb_radar_camera.tools.recording.foxglove_views",
                "aeb_radar_camera.tools.recording.reader",
                "aeb_radar_camera.tools.recording.writer",
                "aeb_radar_camera.tools.recording.rerun_fusion",
                "aeb_radar_camera.tools.recording.rerun_radar",
                "aeb_radar_camera.tools.recording.evidence_frames",
                "aeb_radar_camera.tools.recording.replay",
                "aeb_radar_camera.tools.foxglove.bridge", "aeb_radar_camera.tools.ab.main"]),
    ("eval", ["aeb_radar_camera.tools.eval.cli", "aeb_radar_camera.tools.eval.train_verifier",
              "aeb_radar_camera.tools.eval.frames",
              "aeb_radar_camera.tools.eval.sampling", "aeb_radar_camera.tools.eval.labelweb",
              "distributed"]),
])
def test_each_roles_extra_is_enough_for_its_commands(extra, modules):
    imports = "\n".join(f"import {m}" for m in modules)
    r = run_without(OPTIONAL - extra_modules(extra), imports)
    assert r.returncode == 0, r.stderr


def test_a_missing_extra_is_named_not_a_traceback():
    r = run_without({"can"}, "import sys\nfrom aeb_radar_camera.tools.cli import main\n"
                             "sys.exit(main(['radar', '--config', 'deploy/radar.toml']))")
    assert r.returncode == 2
    assert "pip install 'aeb-radar-camera[radar]'" in r.stderr
    assert "Traceback" not in r.stderr


# Commands whose module imports what only their extra installs: --help gives their
# description and what to install for the options (services and modules owned elsewhere).
DESCRIBED_ONLY = {"radar", "camera", "fusion", "vehicle", "calib-check", "demo", "faults"}


def test_every_commands_help_works_without_any_extra():
    code = (
        "import contextlib, io, json, sys\n"
        "from aeb_radar_camera.tools.cli import main\n"
        "from aeb_radar_camera.tools.commands import COMMANDS\n"
        "out = {}\n"
        "for name in COMMANDS:\n"
        "    buf = io.StringIO()\n"
        "    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):\n"
        "        try:\n"
        "            code = main([name, '--help'])\n"
        "        except SystemExit as exc:\n"
        "            code = exc.code\n"
        "    out[name] = [code, buf.getvalue()]\n"
        "print(json.dumps(out))\n")
    r = run_without(OPTIONAL, code)
    assert r.returncode == 0, r.stderr
    said = json.loads(r.stdout.splitlines()[-1])
    assert set(said) == set(COMMANDS)
    for name, (code, text) in said.items():
        assert code == 0, f"aeb {name} --help: {text}"
        if name in DESCRIBED_ONLY:
            assert f"aeb {name}: " in text and "pip install 'aeb-radar-camera[" in text, text
        else:
            assert text.startswith(f"usage: aeb {name}"), f"aeb {name} --help: {text}"
            assert "--log-level" in text


@pytest.mark.parametrize(("argv", "wanted"), [
    (["eval", "--help"], ["evaluation (Tables II-V", "{rois,run,report,compare"]),
    (["eval", "compare", "--help"], ["--held-out", "--structures-as-negatives", "--taus"]),
    (["eval", "rois", "--help"], ["--depth {none,lidar,d435}", "--frames-per-task"]),
    (["train-verifier", "--help"], ["the decoded picture", "--seeds", "--folds"]),
])
def test_eval_and_train_verifier_list_their_options_without_the_eval_extra(argv, wanted):
    # Described and with every option, not only "needs the package".
    r = run_without(OPTIONAL, "import sys\nfrom aeb_radar_camera.tools.cli import main\n"
                              f"sys.exit(main({argv!r}))")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"usage: aeb {argv[0]}") and "pip install" not in r.stdout
    for text in wanted:
        assert text in r.stdout, (text, r.stdout)
