"""The ARCOS client/server protocol of a Pioneer 3 base: constants and pure encode/decode functions.

No I/O here: the driver (``onboard.hardware.pioneer``) and the emulator (``onboard.emulators.pioneer``)
both build and parse packets with these functions, and the tests hit them with byte vectors worked
out from the Pioneer 3 Operations Manual (its ARCOS chapter) and checked against ARIA's source.

A packet is ``FA FB``, a count N (bytes after it, checksum included), the command number or packet
type, the arguments, and a big-endian checksum. Integers inside a packet are little-endian.
Every malformed input raises :class:`ArcosError`, whose message names the field.
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from enum import IntEnum

from shared.geometry import wrap_angle

log = logging.getLogger(__name__)

HEADER = b"\xfa\xfb"
MAX_COUNT = 249  # largest N: a packet is at most 252 bytes
MIN_COUNT = 3  # the id byte and the two checksum bytes


class Command(IntEnum):
    """Client-to-robot command numbers. SYNC0/1/2 share their numbers with PULSE/OPEN/CLOSE."""

    PULSE = 0
    OPEN = 1
    CLOSE = 2
    SYNC0 = 0
    SYNC1 = 1
    SYNC2 = 2
    ENABLE = 4
    SETA = 5
    SETV = 6
    SETO = 7
    MOVE = 8
    ROTATE = 9
    SETRV = 10
    VEL = 11
    HEAD = 12
    DHEAD = 13
    CONFIG = 18
    RVEL = 21
    SETRA = 23
    SONAR = 28
    STOP = 29
    VEL2 = 32
    BUMPSTALL = 44
    HOSTBAUD = 50
    E_STOP = 55


# Robot-to-client packet types.
SIP_STOPPED = 0x32
SIP_MOVING = 0x33
SIP_TYPES = (SIP_STOPPED, SIP_MOVING)
CONFIG_PACKET = 0x20

# Argument type bytes.
ARG_INT = 0x3B  # non-negative integer, 2 bytes little-endian
ARG_NEGINT = 0x1B  # negative integer, its absolute value in 2 bytes little-endian
ARG_STRING = 0x2B  # length byte, then the characters

XY_BITS_MASK = 0x7FFF  # XPOS/YPOS use 15 bits
XY_WRAP = 0x8000
THPOS_PER_TURN = 4096
DIFF_CONV_FACTOR = 0.0056  # ARIA's P3-DX value: rad/s per mm/s of (right - left) wheel speed / 2

# DistConvFactor (mm per XPOS/YPOS unit) of controllers without the SH firmware, by SYNC2 subtype.
_LEGACY_DIST_CONV = {"p3dx": 0.485, "p3at": 0.465}
_SIP_MIN_PAYLOAD = 19  # XPOS … SONAR COUNT: offsets 1 … 19 from the type byte
_SIP_IO_BYTES = 5  # after the sonar readings; ARIA reads them when present


class ArcosError(ValueError):
    """A packet or field that breaks the ARCOS protocol; the message names the field."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"ARCOS {field}: {problem}")
        self.field = field


@dataclass(frozen=True)
class Packet:
    """One checked packet: its id (command number or packet type) and the bytes after the id."""

    id: int
    payload: bytes


def checksum(body: bytes) -> int:
    """Sum of big-endian 16-bit words of ``body`` (id and arguments); an odd last byte is XORed in."""
    total = 0
    for i in range(0, len(body) - 1, 2):
        total = (total + (body[i] << 8 | body[i + 1])) & 0xFFFF
    if len(body) % 2:
        total ^= body[-1]
    return total


def encode_arg(arg: int | str | None) -> bytes:
    """A command argument with its type byte (nothing for ``None``)."""
    if arg is None:
        return b""
    if isinstance(arg, bool) or not isinstance(arg, (int, str)):
        raise ArcosError("argument", f"must be an int, a str or None, not {type(arg).__name__}")
    if isinstance(arg, str):
        text = arg.encode("ascii", errors="strict") if arg.isascii() else None
        if text is None or len(text) > MAX_COUNT - 5:
            raise ArcosError("argument", f"string {arg!r} must be ASCII and at most {MAX_COUNT - 5} characters")
        return bytes((ARG_STRING, len(text))) + text
    if not -0xFFFF <= arg <= 0xFFFF:
        raise ArcosError("argument", f"integer {arg} does not fit 16 bits")
    return bytes((ARG_INT if arg >= 0 else ARG_NEGINT,)) + struct.pack("<H", abs(arg))


def build_packet(command: int, arg: int | str | None = None) -> bytes:
    """A complete packet for ``command`` (0-255) with an optional argument."""
    if not 0 <= int(command) <= 0xFF:
        raise ArcosError("command", f"{command} is not a byte")
    return frame(bytes((int(command),)) + encode_arg(arg))


def frame(body: bytes) -> bytes:
    """Header, count and checksum around ``body`` (an id byte and its payload)."""
    if not 1 <= len(body) <= MAX_COUNT - 2:
        raise ArcosError("count", f"body of {len(body)} bytes does not fit a packet")
    return HEADER + bytes((len(body) + 2,)) + body + struct.pack(">H", checksum(body))


def parse_packet(data: bytes) -> Packet:
    """Check one complete packet (header, count, checksum) and split it into id and payload."""
    if data[:2] != HEADER:
        raise ArcosError("header", f"expected FA FB, got {data[:2].hex(' ').upper() or 'nothing'}")
    if len(data) < 3:
        raise ArcosError("count", "missing")
    count = data[2]
    if not MIN_COUNT <= count <= MAX_COUNT:
        raise ArcosError("count", f"{count} is outside [{MIN_COUNT}, {MAX_COUNT}]")
    if len(data) != count + 3:
        raise ArcosError("count", f"says {count + 3} bytes in all, the packet has {len(data)}")
    body, expected = data[3:-2], struct.unpack(">H", data[-2:])[0]
    if checksum(body) != expected:
        raise ArcosError("checksum", f"is {expected:#06x}, the bytes sum to {checksum(body):#06x}")
    return Packet(body[0], bytes(body[1:]))


def parse_arg(payload: bytes) -> int | str | None:
    """The argument of a command packet: ``None``, an integer or a string."""
    if not payload:
        return None
    kind = payload[0]
    if kind in (ARG_INT, ARG_NEGINT):
        if len(payload) < 3:
            raise ArcosError("argument", f"integer needs 2 bytes, got {len(payload) - 1}")
        value = struct.unpack_from("<H", payload, 1)[0]
        return value if kind == ARG_INT else -value
    if kind == ARG_STRING:
        if len(payload) < 2 or len(payload) < 2 + payload[1]:
            raise ArcosError("argument", "string shorter than its length byte")
        return payload[2:2 + payload[1]].decode("latin-1")
    raise ArcosError("argument", f"unknown type byte {kind:#04x}")


class PacketReader:
    """A stream parser: feed it arbitrary chunks, get the valid packets back.

    Garbage and packets with a bad count or checksum are skipped; it resynchronises on the next
    header. It never raises: ``skipped_bytes`` counts what it threw away.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.skipped_bytes = 0

    def feed(self, chunk: bytes) -> list[Packet]:
        self._buffer += chunk
        return list(self._drain())

    def clear(self) -> None:
        self._buffer.clear()

    def _drain(self) -> Iterator[Packet]:
        buf = self._buffer
        while True:
            start = buf.find(HEADER)
            if start < 0:
                keep = 1 if buf[-1:] == HEADER[:1] else 0  # half a header may end the chunk
                self._skip(len(buf) - keep)
                return
            self._skip(start)
            if len(buf) < 3:
                return
            count = buf[2]
            if not MIN_COUNT <= count <= MAX_COUNT:
                self._skip(1)
                continue
            if len(buf) < count + 3:
                return
            raw = bytes(buf[:count + 3])
            try:
                packet = parse_packet(raw)
            except ArcosError as exc:
                log.debug("skipping a bad packet: %s", exc)
                self._skip(1)  # the header may have been garbage: look for the next one inside
                continue
            del buf[:count + 3]
            yield packet

    def _skip(self, n: int) -> None:
        if n > 0:
            del self._buffer[:n]
            self.skipped_bytes += n


@dataclass(frozen=True)
class RobotIdentity:
    """What a robot says in its SYNC2 reply."""

    name: str
    type: str
    subtype: str


def parse_sync2(payload: bytes) -> RobotIdentity:
    """Name, type and subtype: three NUL-terminated strings after the SYNC2 id."""
    parts = payload.split(b"\x00")
    if len(parts) < 4:
        raise ArcosError("sync2", f"expected three NUL-terminated strings, got {payload!r}")
    name, kind, subtype = (p.decode("latin-1") for p in parts[:3])
    return RobotIdentity(name, kind, subtype)


def encode_sync2(identity: RobotIdentity) -> bytes:
    """The payload of a SYNC2 reply (for the emulator)."""
    return b"".join(s.encode("latin-1") + b"\x00" for s in (identity.name, identity.type, identity.subtype))


def dist_conv_factor(subtype: str) -> float:
    """mm per odometry unit: 1.0 on SH controllers (``p3dx-sh``), 0.485 on an older P3-DX, ..."""
    key = subtype.strip().lower()
    if "sh" in key.split("-")[1:]:
        return 1.0
    try:
        return _LEGACY_DIST_CONV[key]
    except KeyError:
        known = ", ".join(sorted(_LEGACY_DIST_CONV))
        raise ArcosError("subtype", f"unknown robot {subtype!r} (known: {known}, or any '-sh')") from None


@dataclass(frozen=True)
class Sip:
    """A standard status packet. Positions are raw (15-bit, see :class:`OdometryUnwrapper`)."""

    moving: bool  # type 0x33
    x_raw: int
    y_raw: int
    theta_rad: float  # in [-pi, pi)
    left_mm_s: int
    right_mm_s: int
    battery_v: float
    left_stall: bool
    right_stall: bool
    front_bumpers: int  # one bit per bumper of the bank next to the left-stall bit
    rear_bumpers: int
    control_rad: float  # the heading set-point
    motors_enabled: bool
    sonar_mm: tuple[tuple[int, int], ...] = ()  # (disc, range) pairs

    @property
    def speed_mm_s(self) -> float:
        return 0.5 * (self.left_mm_s + self.right_mm_s)

    @property
    def turn_rate_rad_s(self) -> float:
        return 0.5 * (self.right_mm_s - self.left_mm_s) * DIFF_CONV_FACTOR

    @property
    def stalled(self) -> bool:
        return self.left_stall or self.right_stall


def thpos_to_rad(thpos: int) -> float:
    return wrap_angle(thpos * 2.0 * math.pi / THPOS_PER_TURN)


def rad_to_thpos(angle_rad: float) -> int:
    """THPOS units in [0, 4096), as the firmware reports them."""
    return round(angle_rad * THPOS_PER_TURN / (2.0 * math.pi)) % THPOS_PER_TURN


_SIP_HEAD = struct.Struct("<HHhhhBHhHBB")


def parse_sip(packet: Packet) -> Sip:
    """A SIP (type 0x32 or 0x33) from its checked packet."""
    if packet.id not in SIP_TYPES:
        raise ArcosError("sip type", f"{packet.id:#04x} is not 0x32 or 0x33")
    p = packet.payload
    if len(p) < _SIP_MIN_PAYLOAD:
        raise ArcosError("sip length", f"{len(p)} bytes, at least {_SIP_MIN_PAYLOAD} needed")
    x, y, th, lvel, rvel, battery, stall, control, flags, _compass, sonars = _SIP_HEAD.unpack_from(p, 0)
    if len(p) < _SIP_MIN_PAYLOAD + 3 * sonars:
        raise ArcosError("sip sonar", f"{sonars} readings announced, {(len(p) - _SIP_MIN_PAYLOAD) // 3} present")
    sonar = tuple(struct.unpack_from("<BH", p, _SIP_MIN_PAYLOAD + 3 * i) for i in range(sonars))
    return Sip(packet.id == SIP_MOVING, x & XY_BITS_MASK, y & XY_BITS_MASK, thpos_to_rad(th), lvel, rvel,
               battery / 10.0, bool(stall & 0x0001), bool(stall & 0x0100), (stall >> 1) & 0x7F,
               (stall >> 9) & 0x7F, thpos_to_rad(control), bool(flags & 0x0001), sonar)


def encode_sip(sip: Sip) -> bytes:
    """A complete SIP packet (for the emulator)."""
    stall = (sip.left_stall | (sip.front_bumpers & 0x7F) << 1 | sip.right_stall << 8
             | (sip.rear_bumpers & 0x7F) << 9)
    body = _SIP_HEAD.pack(sip.x_raw & XY_BITS_MASK, sip.y_raw & XY_BITS_MASK, rad_to_thpos(sip.theta_rad),
                          sip.left_mm_s, sip.right_mm_s, max(0, min(255, round(sip.battery_v * 10))), stall,
                          rad_to_thpos(sip.control_rad), int(sip.motors_enabled), 0, len(sip.sonar_mm))
    body += b"".join(struct.pack("<BH", disc, mm) for disc, mm in sip.sonar_mm)
    body += bytes(_SIP_IO_BYTES)  # gripper state, analog port, analog, digital in, digital out: none here
    return frame(bytes((SIP_MOVING if sip.moving else SIP_STOPPED,)) + body)


class OdometryUnwrapper:
    """Continuous x/y in mm from the 15-bit XPOS/YPOS of successive SIPs."""

    def __init__(self, dist_conv_factor: float) -> None:
        self.dist_conv_factor = dist_conv_factor
        self._last: tuple[int, int] | None = None
        self._total = [0, 0]

    def update(self, x_raw: int, y_raw: int) -> tuple[float, float]:
        """The robot's odometry position in mm, continuous across wraps of the 15-bit fields."""
        if self._last is not None:
            for axis, (now, before) in enumerate(zip((x_raw, y_raw), self._last)):
                delta = (now - before) & XY_BITS_MASK
                if delta > XY_WRAP // 2:  # a robot moves far less than half a wrap between two SIPs
                    delta -= XY_WRAP
                self._total[axis] += delta
        else:
            self._total = [x_raw, y_raw]
        self._last = (x_raw, y_raw)
        return self._total[0] * self.dist_conv_factor, self._total[1] * self.dist_conv_factor
