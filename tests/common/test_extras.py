"""Extras per role: the base install runs the brake and the router, and each role's
extra (pyproject.toml) is enough for its commands. Each check runs in a fresh
interpreter in which the optional packages outside the role cannot be imported."""

import tomllib

import pytest

from tests.extras_support import run_without
from tests.support import REPO

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
# distribution -> the module it provides
MODULE_OF = {"python-can": "can", "numpy": "numpy", "opencv-python-headless": "cv2",
             "simplejpeg": "simplejpeg", "matplotlib": "matplotlib", "cantools": "cantools",
             "pyrealsense2": "pyrealsense2"}
OPTIONAL = set(MODULE_OF.values())

def _dist(requirement: str) -> str:
    for sep in "<>=[;! ":
        requirement = requirement.split(sep)[0]
    return requirement


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
    r = run_without(OPTIONAL, "import sys\nfrom tools.cli import main\n"
                              f"sys.exit(main([{command!r}, '--help']))")
    assert r.returncode == 0, r.stderr
    assert "usage: aeb" in r.stdout


@pytest.mark.parametrize(("extra", "modules"), [
    ("radar", ["services.radar.main"]),
    ("camera", ["services.camera.main", "tools.sim.moving_box"]),
    ("fusion", ["services.fusion.main", "tools.calib.check"]),
    ("monitor", ["tools.monitor.main"]),
    ("vehicle", ["services.vehicle.main"]),
    ("demo", ["tools.demo", "benchmarks.suite", "tools.sim.camera_source"]),
])
def test_each_roles_extra_is_enough_for_its_commands(extra, modules):
    imports = "\n".join(f"import {m}" for m in modules)
    r = run_without(OPTIONAL - extra_modules(extra), imports)
    assert r.returncode == 0, r.stderr


def test_a_missing_extra_is_named_not_a_traceback():
    r = run_without({"can"}, "import sys\nfrom tools.cli import main\n"
                             "sys.exit(main(['radar', '--help']))")
    assert r.returncode == 2
    assert "pip install 'aeb-radar-camera[radar]'" in r.stderr
    assert "Traceback" not in r.stderr
