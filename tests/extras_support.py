"""Run Python code in a fresh interpreter in which some packages cannot be imported: how
a machine without an optional extra sees a command."""

import subprocess
import sys

from tests.support import REPO

_BLOCKER = """
import importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Block())
"""


def run_without(blocked: set[str], code: str) -> subprocess.CompletedProcess[str]:
    """Run `code` where the top-level packages in `blocked` raise ModuleNotFoundError."""
    script = f"BLOCKED = {sorted(blocked)!r}\n{_BLOCKER}\n{code}"
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=REPO)
