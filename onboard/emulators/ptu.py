"""A Directed Perception PTU-D46 emulated at the byte level on a pseudo-terminal.

:class:`PtuMachine` is the unit as a pure state machine: bytes and the time in, bytes out. It
prints a banner and self-calibrates at power-up (ignoring input meanwhile), echoes until ``ED``,
answers tersely after ``FT``, slews both axes with trapezoidal profiles at the speeds and
accelerations set by ``PS``/``TS``/``PA``/``TA`` (power-up values: the PTU-D46 slew of
``shared.limits.PanTiltLimits``), refuses out-of-range positions with a ``!`` message naming the
limit while limits are enforced (``LE``), and with ``LD`` lets an axis run into its limit, stop
there and report ``!P`` / ``!T`` unprompted. ``A`` answers once both axes are still; commands sent
meanwhile wait, as on the unit. :class:`PtuEmulator` serves one on a pseudo-terminal in real time
and exposes the head's angles (``reading()``) so a simulated camera can render from them.
"""

from __future__ import annotations

import logging
import math
import re
import select
import threading
import time
from dataclasses import dataclass

from onboard.devices import PanTiltReading
from onboard.emulators.cable import Cable
from onboard.emulators.pty import PseudoTerminal
from onboard.hardware.ptu_protocol import (BARE_COMMANDS, TYPICAL_RESOLUTION_ARCSEC, VALUED_COMMANDS,
                                           deg_to_positions, positions_to_rad)
from shared.limits import PanTiltLimits

log = logging.getLogger(__name__)

BANNER = (b"Pan-Tilt Controller v3.2.0 (syt PTU-D46 emulator), (C) Directed Perception compatible\r\n"
          b"Initializing...\r\n")
VERSION = "Pan-Tilt Controller v3.2.0 (syt PTU-D46 emulator)"
_TOKEN = re.compile(r"([A-Z]+)([+-]?\d+)?")
_MAX_TOKEN = 16  # longer runs without a delimiter are line noise


@dataclass(frozen=True)
class PtuModel:
    """The emulated unit's fixed properties (a standard PTU-D46)."""

    resolution_arcsec: float = TYPICAL_RESOLUTION_ARCSEC
    pan_min_pos: int = -3090
    pan_max_pos: int = 3090
    tilt_min_pos: int = -907
    tilt_max_pos: int = 604
    max_speed_pos_s: int = 5800  # upper speed limit (PU/TU), about 300°/s
    calibration_s: float = 0.3  # power-up self-calibration (and R); seconds on a real unit
    step_s: float = 0.002  # integration step of the slew


class _Axis:
    """One axis: position, velocity and a target, with speed and acceleration limits."""

    def __init__(self, lo: int, hi: int, speed: float, accel: float):
        self.lo, self.hi = lo, hi
        self.pos = self.vel = 0.0
        self.target = 0
        self.pending: int | None = None  # slaved mode: the target that waits for A
        self.speed, self.accel = speed, accel

    @property
    def moving(self) -> bool:
        return self.vel != 0.0 or self.pos != self.target

    def halt(self) -> None:
        self.target, self.vel = round(self.pos), 0.0
        self.pos = float(self.target)

    def step(self, dt: float) -> bool:
        """Advance ``dt`` seconds; ``True`` if the axis ran into a limit during it."""
        if not self.moving:
            return False
        d = self.target - self.pos
        direction = 1.0 if d > 0 else -1.0
        along = self.vel * direction  # speed towards the target
        if along > 0 and along * along / (2.0 * self.accel) >= abs(d):
            along = max(along - self.accel * dt, 0.0)  # braking
        else:
            along = min(along + self.accel * dt, self.speed)
        self.vel = along * direction
        self.pos += self.vel * dt
        if (self.target - self.pos) * direction <= 0.0 or (along == 0.0 and abs(self.target - self.pos) < 1.0):
            self.pos, self.vel = float(self.target), 0.0
        if not self.lo <= self.pos <= self.hi:  # the hard stop (targets beyond it only with LD)
            self.pos = float(min(max(self.pos, self.lo), self.hi))
            self.target, self.vel = round(self.pos), 0.0
            return True
        return False


class PtuMachine:
    """The unit's state machine. Every method takes the current time in seconds (any origin)."""

    def __init__(self, model: PtuModel = PtuModel(), slew: PanTiltLimits = PanTiltLimits()):
        self.model = model
        res = model.resolution_arcsec
        accel = deg_to_positions(slew.accel_deg_s2, res)
        self.pan = _Axis(model.pan_min_pos, model.pan_max_pos, deg_to_positions(slew.pan_speed_deg_s, res), accel)
        self.tilt = _Axis(model.tilt_min_pos, model.tilt_max_pos, deg_to_positions(slew.tilt_speed_deg_s, res),
                          accel)
        self.echo, self.terse, self.enforce_limits, self.slaved = True, False, True, False
        self._input = bytearray()
        self._time: float | None = None
        self._busy_until = -math.inf  # self-calibrating: input ignored
        self._deferred: str | None = None  # "A" or "R": answered when the unit is free again

    def power_up(self, now_s: float) -> bytes:
        """The banner; the unit then self-calibrates for ``model.calibration_s``."""
        self._time = now_s
        self._busy_until = now_s + self.model.calibration_s
        return BANNER

    def receive(self, data: bytes, now_s: float) -> bytes:
        """Bytes from the host; returns what the unit writes back (echo, replies, events)."""
        out = bytearray(self.advance(now_s))
        if now_s < self._busy_until:
            return bytes(out)  # calibrating: deaf
        for byte in data:  # one at a time: ED stops the echo of what follows it
            if self.echo:
                out.append(byte)
            self._input.append(byte)
            if byte in b" \r\n" or len(self._input) > _MAX_TOKEN:
                out += self._execute_ready()
        return bytes(out)

    def advance(self, now_s: float) -> bytes:
        """Move the axes up to ``now_s``; returns unprompted output (``!P``, ``!T``, deferred ``*``)."""
        out = bytearray()
        t = now_s if self._time is None else self._time
        while t < now_s:
            dt = min(self.model.step_s, now_s - t)
            t += dt
            for axis, mark in ((self.pan, b"!P\r\n"), (self.tilt, b"!T\r\n")):
                if axis.step(dt):
                    out += mark
        self._time = now_s
        if self._deferred and now_s >= self._busy_until and not self.moving:
            if self._deferred == "R":
                self.pan.pos = self.tilt.pos = 0.0
            self._deferred = None
            out += b"*\r\n"
            out += self._execute_ready()
        return bytes(out)

    @property
    def moving(self) -> bool:
        return self.pan.moving or self.tilt.moving

    def reading(self) -> PanTiltReading:
        res = self.model.resolution_arcsec
        return PanTiltReading(positions_to_rad(self.pan.pos, res), positions_to_rad(self.tilt.pos, res), self.moving)

    # ------------------------------------------------------------------------- commands

    def _execute_ready(self) -> bytes:
        """Run every complete command in the input, up to one that defers its answer."""
        out = bytearray()
        while self._deferred is None:
            ends = [i for i in (self._input.find(b" "), self._input.find(b"\r"), self._input.find(b"\n")) if i >= 0]
            if not ends:
                if len(self._input) > _MAX_TOKEN:
                    self._input.clear()
                    out += self._error("Illegal command: too long")
                break
            end = min(ends)
            token = self._input[:end].decode("latin-1").upper()
            del self._input[: end + 1]
            if token:
                out += self._execute(token)
        return bytes(out)

    def _execute(self, token: str) -> bytes:
        match = _TOKEN.fullmatch(token)
        if match is None:
            return self._error(f"Illegal command {token!r}")
        name, digits = match.groups()
        value = None if digits is None else int(digits)
        if name not in VALUED_COMMANDS and name not in BARE_COMMANDS:
            return self._error(f"Illegal command {name}")
        if value is not None and name not in VALUED_COMMANDS:
            return self._error(f"Illegal argument: {name} takes none")
        if name in VALUED_COMMANDS:
            return self._valued(name, value)
        return self._bare(name)

    def _valued(self, name: str, value: int | None) -> bytes:
        axis = self.pan if name[0] == "P" else self.tilt
        label = "pan" if axis is self.pan else "tilt"
        kind = name[1]
        if value is None:
            current = {"P": round(axis.pos), "O": round(axis.pos), "S": round(axis.speed),
                       "A": round(axis.accel)}[kind]
            what = {"P": "position", "O": "position", "S": "speed", "A": "acceleration"}[kind]
            return self._answer(f"Current {label} {what} is {current}", current)
        if kind in "PO":
            target = value if kind == "P" else axis.target + value
            if self.enforce_limits and not axis.lo <= target <= axis.hi:
                lo_name, hi_name = name[0] + "N", name[0] + "X"
                return self._error(f"{name}{value}: {label} position {target} is outside the limits "
                                   f"{lo_name} {axis.lo} .. {hi_name} {axis.hi}")
            if self.slaved:
                axis.pending = target
            else:
                axis.target = target
            return b"*\r\n"
        if kind == "S":
            if not 1 <= value <= self.model.max_speed_pos_s:
                return self._error(f"{name}{value}: {label} speed must be 1 .. the upper speed limit "
                                   f"{name[0]}U {self.model.max_speed_pos_s}")
            axis.speed = float(value)
            return b"*\r\n"
        if value < 1:
            return self._error(f"{name}{value}: {label} acceleration must be positive")
        axis.accel = float(value)
        return b"*\r\n"

    def _bare(self, name: str) -> bytes:
        m = self.model
        queries = {"PN": m.pan_min_pos, "PX": m.pan_max_pos, "TN": m.tilt_min_pos, "TX": m.tilt_max_pos,
                   "PU": m.max_speed_pos_s, "TU": m.max_speed_pos_s}
        if name in queries:
            return self._answer(f"{name} limit is {queries[name]}", queries[name])
        if name in ("PR", "TR"):
            return self._answer(f"{m.resolution_arcsec} seconds arc per position", m.resolution_arcsec)
        if name == "V":
            return f"* {VERSION}\r\n".encode("ascii")
        if name in ("H", "HP", "HT"):
            for axis in {"H": (self.pan, self.tilt), "HP": (self.pan,), "HT": (self.tilt,)}[name]:
                axis.halt()
            return b"*\r\n"
        if name == "A":
            for axis in (self.pan, self.tilt):  # slaved mode: A starts the pending moves
                if axis.pending is not None:
                    axis.target, axis.pending = axis.pending, None
            if self.moving:
                self._deferred = "A"
                return b""
            return b"*\r\n"
        if name == "R":
            self.pan.halt()
            self.tilt.halt()
            self._busy_until = (self._time or 0.0) + m.calibration_s
            self._deferred = "R"
            return b""
        self._set_mode(name)
        return b"*\r\n"

    def _set_mode(self, name: str) -> None:
        if name in ("ED", "EE"):
            self.echo = name == "EE"
        elif name in ("FT", "FV"):
            self.terse = name == "FT"
        elif name in ("LE", "LD"):
            self.enforce_limits = name == "LE"
        else:  # I or S
            self.slaved = name == "S"

    def _answer(self, verbose: str, value: float) -> bytes:
        return f"* {value if self.terse else verbose}\r\n".encode("ascii")

    @staticmethod
    def _error(message: str) -> bytes:
        return f"! {message}\r\n".encode("latin-1", "replace")


# ----------------------------------------------------------------------------- pseudo-terminal


class PtuEmulator:
    """A :class:`PtuMachine` served in real time on a pseudo-terminal (``device_path``)."""

    def __init__(self, model: PtuModel = PtuModel(), slew: PanTiltLimits = PanTiltLimits(),
                 tick_s: float = 0.005):
        self.machine = PtuMachine(model, slew)
        self._tick_s = tick_s
        self._lock = threading.Lock()
        self._pty = PseudoTerminal()
        self.device_path = self._pty.path
        self._stop = threading.Event()
        self.cable = Cable()
        self._thread = threading.Thread(target=self._serve, name="ptu-emulator", daemon=True)

    def __enter__(self) -> PtuEmulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        with self._lock:
            self._pty.write(self.machine.power_up(time.monotonic()))
        self._thread.start()
        log.info("PTU-D46 emulator on %s", self.device_path)

    def reading(self) -> PanTiltReading:
        """The head's true angles now (thread-safe), e.g. for a simulated camera."""
        with self._lock:  # the serving thread advances the machine every tick
            return self.machine.reading()

    def inject(self, data: bytes) -> None:
        """Write raw bytes to the host as if the unit sent them (line noise, a stray ``!P``)."""
        with self._lock:
            self._pty.write(data)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._pty.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            select.select([self._pty.master_fd], [], [], self._tick_s)
            try:
                data = self._pty.read()
            except OSError:  # EIO: the terminal is gone or unusable; wait, keep serving
                data = b""
                time.sleep(self._tick_s)
            with self._lock:
                now = time.monotonic()
                heard = data if self.cable.hears else b""
                said = self.machine.receive(heard, now) if heard else self.machine.advance(now)
                if self.cable.talks:
                    self._pty.write(said)
