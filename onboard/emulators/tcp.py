"""A TCP port that an emulator serves on, as the vendor's simulators serve ARCOS (port 8101)."""

from __future__ import annotations

import select
import socket


class TcpPort:
    """Listens on ``host:port`` (0 picks a free port) and serves one client at a time; a new client
    replaces the old one. ``path`` is the pyserial URL a driver opens (``socket://HOST:PORT``)."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0):
        self._listener = socket.create_server((host, port))
        self._listener.setblocking(False)
        self._client: socket.socket | None = None
        bound_host, bound_port = self._listener.getsockname()[:2]
        self.path = f"socket://{bound_host}:{bound_port}"

    def wait_readable(self, timeout_s: float) -> bool:
        """Accept a new client if one knocks; True if the client sent bytes."""
        sockets = [self._listener] + ([self._client] if self._client else [])
        ready = select.select(sockets, [], [], timeout_s)[0]
        if self._listener in ready:
            client, _ = self._listener.accept()
            client.setblocking(False)
            self._drop_client()
            self._client = client
        return self._client is not None and self._client in ready

    def read(self, size: int = 4096) -> bytes:
        if self._client is None:
            return b""
        try:
            data = self._client.recv(size)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:  # the client hung up
            self._drop_client()
        return data

    def write(self, data: bytes) -> None:
        """Send to the client, if there is one; dropped if it does not keep up, as on a cable."""
        if self._client is None:
            return
        view = memoryview(data)
        try:
            while view:
                view = view[self._client.send(view):]
        except BlockingIOError:
            pass
        except OSError:
            self._drop_client()

    def close(self) -> None:
        self._drop_client()
        self._listener.close()

    def _drop_client(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def __enter__(self) -> TcpPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
