"""`aeb faults fuzz` at the scale and seed docs/reliability.md gives for the test suite,
as a process: 0 crashes, and the number of inputs the document states for that command
(the figures a reader finds there are the ones CI reproduces). `.ci/run` runs the full
scale at the same seed after the suite."""

import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "reliability.md"
COMMAND = "python -m aeb_radar_camera.tools.faults.fuzz --scale 0.1 --seed 19"


def documented(command: str) -> tuple[int, int]:
    """(inputs, crashes) of the row of the document's table that runs `command`."""
    for line in DOC.read_text().splitlines():
        if f"`{command}`" in line:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            return int(cells[-2].replace(",", "")), int(cells[-1])
    raise AssertionError(f"{DOC} has no row for `{command}`")


def test_the_ci_scale_fuzz_run_finds_no_crash_and_the_documented_count(tmp_path):
    inputs, crashes = documented(COMMAND)
    argv = COMMAND.split()[3:]
    run = subprocess.run([sys.executable, "-m", "aeb_radar_camera.tools.faults.fuzz", *argv,
                          "--out",
                          str(tmp_path)], capture_output=True, text=True, timeout=280,
                         cwd=REPO)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    total = re.search(r"^(\d+) crashes in ([\d,]+) inputs", run.stdout, re.MULTILINE)
    assert total is not None, run.stdout[-2000:]
    assert (int(total[2].replace(",", "")), int(total[1])) == (inputs, crashes), (
        f"{DOC} documents {inputs:,} inputs and {crashes} crashes for `{COMMAND}`; "
        f"this build gives the table in {tmp_path / 'fuzz.md'}: update the document")
    assert (tmp_path / "fuzz.json").is_file()
