"""What a figure was measured on (CPU, cores, Python, kernel, load, the versions of the
dependencies that set the speed): written beside every benchmark's and evaluation's
figures."""

import os
import platform
from importlib import metadata
from typing import Any


def machine_info() -> dict[str, Any]:
    """What the figures were measured on."""
    cpu = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    versions = {}
    for dist in ("eclipse-zenoh", "python-can", "opencv-python-headless", "numpy", "msgspec",
                 "pyserial", "simplejpeg"):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = "not installed"
    load = os.getloadavg() if hasattr(os, "getloadavg") else (0.0, 0.0, 0.0)
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "kernel": platform.release(),
        "load_avg_1_5_15": [round(x, 2) for x in load],
        "versions": versions,
    }
