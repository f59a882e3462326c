"""The secure profile (deploy/zenoh/secure/) on loopback for the brake's process tests:
certificates made by its script into a temporary folder, the shipped router and client
files with their paths and endpoints pointed there."""

import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from aeb_radar_camera.common.resources import DEPLOY
from tests.support import (
    START_TIMEOUT_S,
    ServiceProcess,
    free_port,
    port_open,
    python_module,
    wait_for,
)

SECURE = DEPLOY / "zenoh" / "secure"
OPENSSL = shutil.which("openssl") is not None


@dataclass(frozen=True)
class SecureProfile:
    endpoint: str
    folder: Path

    def client(self, name: str) -> Path:
        """The client file of `name` (brake, fusion, fusion-candidate, monitor, ...)."""
        return self.folder / f"client-{name}.json5"


def _localised(text: str, certs: Path, endpoint: str) -> str:
    return (text.replace("/etc/aeb/tls/", f"{certs}/")
            .replace('["tls/127.0.0.1:7447", "tls/192.168.10.1:7447"]', f'["{endpoint}"]')
            .replace("tls/192.168.10.1:7447", endpoint))


@contextmanager
def secure_router(log_dir: Path) -> Iterator[SecureProfile]:
    """Certificates, router and client files in `log_dir`; the router running (as its own
    process) and accepting connections."""
    certs = log_dir / "certs"
    subprocess.run(["sh", str(SECURE / "make-certs.sh"), str(certs)], check=True,
                   capture_output=True, timeout=120)
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"
    for path in SECURE.glob("*.json5"):
        (log_dir / path.name).write_text(_localised(path.read_text(), certs, endpoint))
    proc = ServiceProcess(f"router-{port}", python_module(
        "aeb_radar_camera.common.router", "--config-file", str(log_dir / "router.json5")), log_dir)
    try:
        wait_for(lambda: port_open(port) or not proc.alive(), START_TIMEOUT_S, 0.05,
                 "secure router port")
        if not proc.alive():
            raise RuntimeError(f"router exited:\n{proc.output()}")
        yield SecureProfile(endpoint, log_dir)
    finally:
        proc.stop()
