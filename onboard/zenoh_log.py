"""Zenoh's own word on refused peers, in the agent's log.

Zenoh (Rust) decides TLS handshakes and access control before the agent sees anything, and says so only in
its own log, which it writes to standard output. The agent routes that output through a pipe and keeps what
an operator needs: warnings and errors (in 1.10.2 a refused TLS handshake is a warning of
``zenoh_link_tls``), accepted TLS peers with their certificate's name, peers that match no access-control
subject, and every message the access-control list drops.

Access control reports a drop at trace level only, among a flood of permitted messages and of the
permissions it works out once per key ("caching permissions for `KEY`", then one line per kind of message,
none of them a message that arrived). :class:`ZenohLogFilter` tells the drops apart.
"""

from __future__ import annotations

import logging
import os
import re
import threading
from dataclasses import dataclass

import zenoh

log = logging.getLogger("syt.zenoh")

# Zenoh's levels for what the filter reads; RUST_LOG, if set, replaces this.
ZENOH_LOG_LEVELS = "warn,zenoh_link_tls=debug,zenoh::net::routing::interceptor::access_control=trace"

_ANSI = re.compile(r"\x1b\[[0-9;]*m")
# 2026-11-22T17:26:01.645317Z TRACE acc-0 ThreadId(06) zenoh::...::access_control: MESSAGE
_LINE = re.compile(r"^\S+\s+(?P<level>TRACE|DEBUG|INFO|WARN|ERROR)\s+(?:\S+\s+)?(?P<thread>ThreadId\(\d+\))\s+"
                   r"(?P<target>[\w:]+):\s(?P<message>.*)$")
_CACHING = re.compile(r"caching permissions for `(?P<key>[^`]+)`")
_DECISION = re.compile(r"^(?P<cached>Using cached result: )?(?P<who>.+?) is (?P<verdict>authorized|unauthorized) "
                       r"to (?P<what>.+?) on (?P<key>\S+)$")
_ACL = "access_control"
_TLS_HINT = " Hint: increase the system open file limit."  # zenoh 1.10.2 appends it to every refused handshake
# What access control says while it works out a key's permissions in advance (real messages say "Declare
# Queryable", not "Declare/Undeclare Queryable", or come "Using cached result").
_ADVANCE = {f"{what} ({flow})" for flow in ("ingress", "egress") for what in (
    "Query", "Reply", "Put", "Delete", "Declare/Undeclare Subscriber", "Declare/Undeclare Queryable",
    "Declare/Undeclare Liveliness Token", "Liveliness Query", "Declare Liveliness Subscriber")}


@dataclass(frozen=True)
class Entry:
    """A line worth the agent's log."""

    level: int
    message: str


class ZenohLogFilter:
    """Reads Zenoh's log lines one at a time and returns the few worth keeping."""

    def __init__(self) -> None:
        self._caching: dict[str, str] = {}  # thread -> the key whose permissions it is working out

    def feed(self, raw: str) -> Entry | None:
        match = _LINE.match(_ANSI.sub("", raw).strip())
        if match is None:
            return None
        level, thread, target, message = match.group("level", "thread", "target", "message")
        if target.endswith(_ACL):
            return self._access_control(thread, level, message)
        self._caching.pop(thread, None)
        if level in ("WARN", "ERROR"):
            if target.startswith("zenoh_link_tls"):  # a refused handshake; its hint is about something else
                message = "TLS: " + message.replace(_TLS_HINT, "")
            return Entry(logging.ERROR if level == "ERROR" else logging.WARNING, f"{target}: {message}")
        if "Can not accept TLS connection" in message:
            return Entry(logging.WARNING, f"TLS peer refused: {message}")
        if "Accepted TLS connection" in message:
            return Entry(logging.INFO, f"TLS peer accepted: {message}")
        return None

    def _access_control(self, thread: str, level: str, message: str) -> Entry | None:
        if caching := _CACHING.search(message):
            self._caching[thread] = caching.group("key")
            return None
        decision = _DECISION.match(message)
        if decision is None:
            self._caching.pop(thread, None)
            if "did not match any configured ACL subject" in message or level in ("WARN", "ERROR"):
                return Entry(logging.WARNING, f"access control: {message}")
            return None
        if (not decision.group("cached") and decision.group("what") in _ADVANCE
                and self._caching.get(thread) == decision.group("key")):
            return None  # working out a permission in advance, not a message that arrived
        self._caching.pop(thread, None)
        if decision.group("verdict") == "authorized":
            return None
        return Entry(logging.WARNING, "access control dropped {} on {} (peer {})".format(
            decision.group("what"), decision.group("key"), decision.group("who").split(" on ", 1)[-1]))


def route_zenoh_log() -> None:
    """Send Zenoh's log (its standard output) through :class:`ZenohLogFilter` into this process's log.

    Call once, before the first session opens. The agent writes nothing to standard output itself.
    """
    read_fd, write_fd = os.pipe()
    os.dup2(write_fd, 1)
    os.close(write_fd)
    threading.Thread(target=_pump, args=(read_fd,), name="zenoh-log", daemon=True).start()
    zenoh.init_log_from_env_or(ZENOH_LOG_LEVELS)


def _pump(read_fd: int) -> None:
    keep = ZenohLogFilter()
    with os.fdopen(read_fd, "r", errors="replace") as lines:
        for line in lines:
            if (entry := keep.feed(line)) is not None:
                log.log(entry.level, "%s", entry.message)
