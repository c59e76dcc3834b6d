"""A pseudo-terminal pair that an emulator serves on, in place of a serial port."""

from __future__ import annotations

import os
import select
import tty


class PseudoTerminal:
    """The emulator keeps the master end; a client opens ``path`` (the slave) as a serial port.

    The slave end stays open here too, so a client may close and reopen the port (as a driver
    does when it reconnects) without the master seeing end-of-file. The master is non-blocking:
    bytes written while nobody reads are lost once the terminal's buffer is full, as on a cable.
    """

    def __init__(self) -> None:
        self.master_fd, self._slave_fd = os.openpty()
        tty.setraw(self._slave_fd)  # no echo, no line editing, no CR/LF translation: bytes pass as they are
        os.set_blocking(self.master_fd, False)
        self.path = os.ttyname(self._slave_fd)

    def wait_readable(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for bytes from the client."""
        return bool(select.select([self.master_fd], [], [], timeout_s)[0])

    def read(self, size: int = 4096) -> bytes:
        """What the client wrote (empty if nothing is waiting)."""
        try:
            return os.read(self.master_fd, size)
        except BlockingIOError:
            return b""

    def write(self, data: bytes) -> None:
        """Send to the client; dropped if its input buffer is full (nobody is reading)."""
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self.master_fd, view):]
        except BlockingIOError:
            pass

    def close(self) -> None:
        for fd in (self.master_fd, self._slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass  # already closed

    def __enter__(self) -> PseudoTerminal:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
