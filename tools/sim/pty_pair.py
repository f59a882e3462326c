"""A pseudo-terminal pair behind a stable path, standing in for a USB serial device.

The actuator side keeps the master; the host opens `path` (a symlink to the slave, e.g.
/dev/pts/7) with pyserial exactly as it would open /dev/ttyACM0. `recreate()` closes the
pair (the host's port fails with EIO, like an unplugged device) and makes a new one
behind the same path (like the device coming back, possibly under another /dev name).
"""

import contextlib
import os
import tty
from pathlib import Path


class PtyPair:
    """Raises OSError when the pty or the symlink cannot be created."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.master_fd = -1
        self._slave_fd = -1
        self.slave_name = ""
        self._open()

    def _open(self) -> None:
        master, slave = os.openpty()
        # raw on both ends at once: no echo, no line discipline before the host opens it
        tty.setraw(master)
        tty.setraw(slave)
        os.set_blocking(master, False)
        # the held slave fd keeps the master readable (no EIO) while no host has it open
        self.master_fd, self._slave_fd = master, slave
        self.slave_name = os.ttyname(slave)
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        os.symlink(self.slave_name, tmp)
        os.replace(tmp, self.path)   # atomic: the path never disappears between pairs

    def close(self) -> None:
        """Close both ends (the host sees its port fail). The symlink stays, dangling."""
        for fd in (self.master_fd, self._slave_fd):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master_fd = self._slave_fd = -1

    def recreate(self) -> int:
        """A new pair behind the same path; returns the new master fd."""
        self.close()
        self._open()
        return self.master_fd

    def remove(self) -> None:
        """Close and delete the symlink."""
        self.close()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
