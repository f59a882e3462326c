"""The README's two commands do all the set-up on a fresh machine: the test command
installs the headless Chromium the labelling page's test needs (tests/setup/chromium,
Debian's package through apt) when none is on PATH, and .ci/run runs exactly that
command. The install is checked with stand-ins for apt-get and sudo on a PATH without
Chromium (the real one, `apt-get remove chromium` then the README's command, is in the
report of the change that made it)."""

import os
import re
import subprocess
from pathlib import Path

from tests.support import REPO

SETUP = REPO / "tests" / "setup" / "chromium"


def readme_commands() -> list[str]:
    block = re.search(r"```sh\n(.*?)```", (REPO / "README.md").read_text(), re.S)
    assert block is not None
    return [ln for ln in block[1].splitlines() if ln.strip()]


def test_the_readme_test_command_sets_up_chromium_and_ci_runs_it_as_written():
    install, test = readme_commands()
    assert test.startswith("tests/setup/chromium && ") and test.endswith("-m pytest")
    assert "'.[demo,record]'" in install          # what the README says it installs
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert test in ci


def _stubs(tmp_path: Path, uid: int, chromium: bool) -> tuple[dict[str, str], Path]:
    """A PATH of stand-ins: apt-get and sudo log their arguments, id says `uid`."""
    bin_dir, log = tmp_path / "bin", tmp_path / "calls.log"
    bin_dir.mkdir()
    scripts = {
        "apt-get": f'echo "apt-get $*" >> {log}',
        "sudo": f'echo "sudo" >> {log}; exec "$@"',
        "id": f"echo {uid}",
        "env": 'while [ "${1#*=}" != "$1" ]; do export "$1"; shift; done; exec "$@"',
    }
    if chromium:
        scripts["chromium"] = "exit 0"
    for name, body in scripts.items():
        path = bin_dir / name
        path.write_text(f"#!/bin/bash\n{body}\n")
        path.chmod(0o755)
    return {"PATH": str(bin_dir), "HOME": str(tmp_path)}, log


def run_setup(env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["/bin/bash", str(SETUP)], env=env, capture_output=True, text=True,
                          timeout=60)


def test_without_chromium_the_setup_installs_debians_package(tmp_path):
    env, log = _stubs(tmp_path, uid=0, chromium=False)
    done = run_setup(env)
    assert done.returncode == 0, done.stderr
    assert log.read_text().splitlines() == [
        "apt-get update -q",
        "apt-get install -y -q --no-install-recommends chromium"]


def test_as_a_user_the_install_goes_through_sudo(tmp_path):
    env, log = _stubs(tmp_path, uid=1000, chromium=False)
    assert run_setup(env).returncode == 0
    assert log.read_text().splitlines() == [
        "sudo", "apt-get update -q",
        "sudo", "apt-get install -y -q --no-install-recommends chromium"]


def test_with_chromium_on_path_nothing_is_installed(tmp_path):
    env, log = _stubs(tmp_path, uid=0, chromium=True)
    assert run_setup(env).returncode == 0
    assert not log.exists()


def test_the_setup_is_executable_as_the_readme_runs_it():
    assert os.access(SETUP, os.X_OK)
