"""The Directed Perception PTU-D46 ASCII protocol, pure: commands out, replies in, no I/O.

A command is letters, an optional signed integer, then a delimiter (a space here)::

    PP1000     pan to position 1000          TP         query the tilt position
    PS1167     pan speed, positions/s         PR         query the pan resolution (arc-seconds)

The unit answers each command with one line: ``*`` (done), ``* <value>`` (a query's answer) or
``! <message>`` (refused). ``!P`` / ``!T`` arrive unprompted when the pan / tilt axis hits a limit.
Lines end in CR LF. With echo on (the power-up default, until ``ED``) the command's characters
come back before the reply on the same line, so a reply may follow an echoed command.

:class:`ReplyTokenizer` takes the byte stream in arbitrary chunks and yields :class:`Reply`,
:class:`LimitHit` and :class:`Noise` (banners, echoes, garbage) events; it never raises, drops
over-long lines and resyncs at the next line end. Everything that goes wrong with the unit is a
:class:`PtuError` whose message starts with the command it concerns.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal

from onboard.devices import DeviceFault

TYPICAL_RESOLUTION_ARCSEC = 185.1428  # arc-seconds per position (0.0514°), PTU-D46 standard
MAX_LINE_BYTES = 256  # no reply is longer; a longer "line" is garbage

# Commands taking an optional signed integer (set if given, query if not).
VALUED_COMMANDS = frozenset({"PP", "TP", "PO", "TO", "PS", "TS", "PA", "TA"})
# Commands without an argument: queries of limits, resolution, upper speed and version; modes
# (echo ED/EE, feedback FT/FV, limits LE/LD, immediate I / slaved S); await A; halt H/HP/HT; reset R.
BARE_COMMANDS = frozenset({"PN", "PX", "TN", "TX", "PR", "TR", "PU", "TU", "V", "ED", "EE", "FT", "FV",
                           "LE", "LD", "I", "S", "A", "H", "HP", "HT", "R"})
MAX_ARGUMENT = 99_999  # the unit's integers are at most five digits

_ECHO_THEN_REPLY = re.compile(r"(?:[A-Za-z]{1,3}-?\d{0,6}\s*)?([*!])(.*)")
_INTEGER = re.compile(r"[+-]?\d{1,9}")
_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)")


class PtuError(DeviceFault):
    """The PTU-D46 refused a command, answered what does not parse, or did not answer.

    ``command`` names the command concerned (``"PP"``, ``"look"``...), ``problem`` says what happened;
    the message is ``"<command>: <problem>"``.
    """

    def __init__(self, command: str, problem: str):
        self.command = command
        self.problem = problem
        super().__init__(f"{command}: {problem}")


def command(name: str, value: int | None = None) -> bytes:
    """The bytes of one command, e.g. ``command("PP", -300) == b"PP-300 "``."""
    if name not in VALUED_COMMANDS and name not in BARE_COMMANDS:
        raise PtuError(name, "not a PTU-D46 command this driver knows")
    if value is None:
        return f"{name} ".encode("ascii")
    if name not in VALUED_COMMANDS:
        raise PtuError(name, f"takes no argument (got {value!r})")
    if isinstance(value, bool) or not isinstance(value, int) or abs(value) > MAX_ARGUMENT:
        raise PtuError(name, f"argument must be an integer within ±{MAX_ARGUMENT} (got {value!r})")
    return f"{name}{value} ".encode("ascii")


# ----------------------------------------------------------------------------- replies


@dataclass(frozen=True)
class Reply:
    """The answer to the oldest command: ``*`` (``ok``) or ``!`` (refused); ``text`` follows the mark."""

    ok: bool
    text: str


@dataclass(frozen=True)
class LimitHit:
    """An unsolicited ``!P`` / ``!T``: that axis ran into its limit and stopped."""

    axis: Literal["pan", "tilt"]


@dataclass(frozen=True)
class Noise:
    """A line that answers nothing: the power-up banner, an echo, line noise."""

    text: str


Event = Reply | LimitHit | Noise


def classify_line(line: bytes) -> Event | None:
    """What one line (without its terminator) is; ``None`` for a blank line."""
    text = line.decode("latin-1").strip()
    if not text:
        return None
    if not text.isascii() or not text.isprintable():
        return Noise(text)
    if text in ("!P", "!T"):
        return LimitHit("pan" if text == "!P" else "tilt")
    match = _ECHO_THEN_REPLY.fullmatch(text)
    if match is None:
        return Noise(text)
    mark, rest = match.groups()
    return Reply(mark == "*", rest.strip())


class ReplyTokenizer:
    """Splits the unit's byte stream, fed in any chunks, into events."""

    def __init__(self, max_line_bytes: int = MAX_LINE_BYTES):
        self._max = max_line_bytes
        self._buffer = bytearray()
        self._discarding = False  # inside an over-long line: drop up to its end

    def reset(self) -> None:
        """Forget a partial line (after the port's input was flushed)."""
        self._buffer.clear()
        self._discarding = False

    def feed(self, data: bytes) -> list[Event]:
        events: list[Event] = []
        for byte in data:
            if byte in (0x0D, 0x0A):
                if not self._discarding:
                    event = classify_line(bytes(self._buffer))
                    if event is not None:
                        events.append(event)
                self._buffer.clear()
                self._discarding = False
            elif not self._discarding:
                self._buffer.append(byte)
                if len(self._buffer) > self._max:
                    events.append(Noise(f"<over-long line of more than {self._max} bytes dropped>"))
                    self._buffer.clear()
                    self._discarding = True
        return events


def expect_ok(reply: Reply, name: str) -> str:
    """The reply's text, or :class:`PtuError` naming the command if the unit refused it."""
    if not reply.ok:
        raise PtuError(name, f"refused by the unit: {reply.text or '(no message)'}")
    return reply.text


def parse_integer(reply: Reply, name: str) -> int:
    """A query's integer answer (``* -3090``); a verbose answer's last word is accepted too."""
    text = expect_ok(reply, name)
    word = text.split()[-1] if text.split() else ""
    if not _INTEGER.fullmatch(word):
        raise PtuError(name, f"expected an integer answer, got {text!r}")
    return int(word)


def parse_decimal(reply: Reply, name: str) -> float:
    """A query's decimal answer (``* 185.1428``: the resolution in arc-seconds)."""
    text = expect_ok(reply, name)
    word = text.split()[-1] if text.split() else ""
    if not _DECIMAL.fullmatch(word):
        raise PtuError(name, f"expected a number, got {text!r}")
    return float(word)


# ----------------------------------------------------------------------------- units


def positions_to_rad(positions: float, resolution_arcsec: float) -> float:
    return math.radians(positions * resolution_arcsec / 3600.0)


def rad_to_positions(angle_rad: float, resolution_arcsec: float) -> int:
    """The nearest whole position to an angle."""
    return round(math.degrees(angle_rad) * 3600.0 / resolution_arcsec)


def deg_to_positions(angle_deg: float, resolution_arcsec: float) -> float:
    """Degrees (or degrees/s, degrees/s²) in positions, unrounded."""
    return angle_deg * 3600.0 / resolution_arcsec
