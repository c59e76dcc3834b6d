"""One request/reply exchange over a Zenoh query, with the reply decoded and checked."""

from __future__ import annotations

import time
from typing import Any, TypeVar

import zenoh

from shared.codec import ProtocolError, decode, encode
from shared.messages import ErrorReply

T = TypeVar("T")


class CommandError(RuntimeError):
    """The robot answered with an ErrorReply (``code``: protocol, limit, busy or device)."""

    def __init__(self, key: str, reply: ErrorReply):
        super().__init__(f"{key}: {reply.code}: {reply.message}")
        self.code = reply.code
        self.reply = reply


class RobotUnavailable(RuntimeError):
    """Nobody answered in time: the agent is not running, unreachable or stuck."""


def request(session: zenoh.Session, key: str, command: Any, expected: type[T], timeout_s: float,
            sender: str | None = None) -> T:
    """Send ``command`` to the queryable at ``key``, naming its ``sender`` (a planner's id, as its
    heartbeats do: the agent's watchdog keeps a motion alive on its sender's word only); return the
    decoded reply or raise."""
    started = time.monotonic()
    replies = session.get(key, payload=encode(command), timeout=timeout_s, attachment=sender)
    for reply in replies:
        if reply.ok is not None:
            result = decode(reply.ok.payload.to_bytes(), expected)
            echoed = getattr(result, "command_id", None)
            if echoed is not None and echoed != command.command_id:
                raise ProtocolError("command_id", echoed, f"reply does not echo {command.command_id!r}")
            return result
        payload = reply.err.payload.to_bytes()
        if payload == b"Timeout":  # Zenoh's own answer to a query held past its timeout
            raise RobotUnavailable(f"no reply from {key} within {timeout_s:g} s: {_ASK}")
        try:
            error = decode(payload, ErrorReply)
        except ProtocolError:  # not the agent's answer: Zenoh's own (a dropped route)
            raise RobotUnavailable(f"{key}: {payload[:200].decode('utf-8', 'replace')}") from None
        raise CommandError(key, error)
    # no reply at all: Zenoh ended the query, as nobody serves the key or its server went away
    raise RobotUnavailable(f"nobody answered {key} (the query ended after {time.monotonic() - started:.1f} s of its "
                           f"{timeout_s:g}): {_ASK}")


_ASK = "is the onboard agent running and reachable (--connect/--listen)?"
