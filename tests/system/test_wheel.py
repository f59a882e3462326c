"""The package as a user installs it: the built wheel in a fresh virtual environment,
used from another directory, finds its configs, calibration, scenarios and bundled
recording, and runs the demo's shortest scenario. Dependencies come from the package
registry (pip's cache makes a second run quick)."""

import os
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from tests.support import REPO

pytestmark = pytest.mark.slow

_NOT_SOURCE = shutil.ignore_patterns(".venv", ".git", "build", "dist", "out", "__pycache__",
                                     "*.egg-info", ".pytest_cache", ".mypy_cache",
                                     ".ruff_cache")
SCENARIO = "stationary_car_30kph"        # the shortest: the ego stops in about 4 s


def run(argv: list[str], cwd: Path, timeout_s: float = 900.0) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    done = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout_s)
    assert done.returncode == 0, f"{argv}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of what a clone holds."""
    root = tmp_path_factory.mktemp("wheel")
    source = root / "source"
    shutil.copytree(REPO, source, ignore=_NOT_SOURCE, symlinks=True)  # what a clone holds
    t0 = time.monotonic()
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(root / "dist"),
         str(source)], root)
    (built,) = (root / "dist").glob("aeb_radar_camera-*.whl")
    print(f"\nwheel built in {time.monotonic() - t0:.0f} s")
    shutil.rmtree(source)            # nothing may come from the source tree any more
    return built


@pytest.fixture(scope="module")
def installed(wheel: Path) -> tuple[Path, Path]:
    """(the fresh venv's bin folder, a working directory outside the source tree)."""
    root = wheel.parent.parent
    t1 = time.monotonic()
    run([sys.executable, "-m", "venv", str(root / "venv")], root)
    run([str(root / "venv/bin/pip"), "install", "-q", f"{wheel}[demo]"], root)
    print(f"\ninstalled with the demo extra in a fresh venv in {time.monotonic() - t1:.0f} s")
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    return root / "venv/bin", elsewhere


def test_the_wheel_installs_one_name_that_cannot_collide(wheel):
    # site-packages is shared: a top-level `common` or `tools` would overwrite, or be
    # overwritten by, any other project's
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        top_level = archive.read(next(n for n in names if n.endswith(".dist-info/top_level.txt")))
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"aeb_radar_camera"}, tops
    assert top_level.decode().split() == ["aeb_radar_camera"]
    for folder in ("common", "services", "tools", "deploy"):
        assert any(n.startswith(f"aeb_radar_camera/{folder}/") for n in names), folder
    assert not any(n.startswith(("benchmarks/", "tests/", "aeb_radar_camera/benchmarks"))
                   for n in names)


def test_the_installed_package_is_the_wheels(installed):
    bin_dir, cwd = installed
    done = run([str(bin_dir / "python"), "-c",
                "import aeb_radar_camera.common.resources as r, aeb_radar_camera.tools.cli as c; "
                "print(r.DEPLOY); print(c.version())"], cwd)
    deploy, version = done.stdout.split()
    assert "site-packages" in deploy and (Path(deploy) / "single-host.toml").is_file()
    assert version == run([str(bin_dir / "aeb"), "--version"], cwd).stdout.split()[1]


def test_the_demos_shortest_scenario_runs_from_another_directory(installed):
    bin_dir, cwd = installed
    t0 = time.monotonic()
    done = run([str(bin_dir / "aeb"), "demo", "--scenarios", SCENARIO, "--out", "demo"], cwd)
    print(f"\naeb demo --scenarios {SCENARIO}: {time.monotonic() - t0:.0f} s")
    assert "1 of 1 scenarios passed" in done.stdout
    assert (cwd / "demo" / f"{SCENARIO}.png").is_file()


def test_shipped_configs_work_from_the_install(installed):
    bin_dir, cwd = installed
    aeb = str(bin_dir / "aeb")
    deploy = Path(run([str(bin_dir / "python"), "-c",
                       "import aeb_radar_camera.common.resources as r; "
                       "print(r.DEPLOY)"], cwd).stdout.strip())
    # a config of the installed deploy/, from elsewhere: its calibration is found
    assert "configuration ok" in run([aeb, "camera", "-c", str(deploy / "camera-sim.toml"),
                                      "--check"], cwd).stdout
    run([aeb, "init", "car"], cwd)
    assert "configuration ok" in run([aeb, "radar", "-c", "car/radar-replay.toml", "--check"],
                                     cwd).stdout           # the bundled recording
    checked = run([aeb, "up", "--check", "--table", "car/ecu-b.toml"], cwd).stdout
    assert "ok      fusion: configuration ok" in checked
