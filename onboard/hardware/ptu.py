"""The Directed Perception PTU-D46 pan-tilt unit over a serial line: the ``PanTilt`` of the hardware backend.

Start-up: the unit may still be printing its banner and self-calibrating, so the driver repeats
``ED`` (echo off) until the unit answers, flushes what came before, then sets ``FT`` (terse
answers), ``LE`` (limits enforced) and ``I`` (immediate moves), reads the resolution (``PR``/``TR``)
and the position limits (``PN PX TN TX``) from the unit, and sets the slew speeds and acceleration
of the configured ``PanTiltLimits`` so that the planner's time model holds. ``limits`` is the
intersection of the configured limits and the unit's.

A look sends ``PP``/``TP`` and polls the positions until both arrive (or a timeout, a cancel, a
halt); the publisher's ``reading()`` returns the last polled angles without touching the port.
A ``!`` answer becomes a :class:`PtuError` naming the command; an unprompted ``!P``/``!T`` is logged
and fails the look under way.
"""

from __future__ import annotations

import collections
import logging
import math
import threading
import time
from dataclasses import replace

import serial

from onboard.config import PtuConfig
from onboard.devices import PanTiltReading
from onboard.hardware.ptu_protocol import (Event, LimitHit, Noise, PtuError, Reply, ReplyTokenizer,
                                           command, deg_to_positions, parse_decimal, parse_integer,
                                           positions_to_rad, rad_to_positions)
from shared.limits import PanTiltLimits

log = logging.getLogger(__name__)


class PtuLink:
    """One serial port to a unit: one command, one answer, unprompted events set aside."""

    def __init__(self, port: str, baud: int, reply_timeout_s: float):
        if port == "sim":
            raise PtuError("open", "port 'sim' selects the simulated pan-tilt, not a serial device")
        try:
            self._serial = serial.serial_for_url(port, baudrate=baud, timeout=0.02, write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PtuError("open", f"cannot open {port!r}: {exc}") from exc
        self.port = port
        self._reply_timeout_s = reply_timeout_s
        self._tokenizer = ReplyTokenizer()
        self._events: collections.deque[Event] = collections.deque()
        self._stale = False  # a reply may still be on its way: flush before the next command
        self.limit_hits: list[str] = []  # axes that reported !P / !T since last cleared

    def flush(self) -> None:
        try:
            self._serial.reset_input_buffer()
        except (serial.SerialException, OSError) as exc:  # as every other I/O here: a PtuError naming the port
            raise PtuError("flush", f"cannot flush {self.port}: {exc}") from exc
        self._tokenizer.reset()
        self._events.clear()

    def transact(self, name: str, value: int | None = None, timeout_s: float | None = None) -> Reply:
        """Send one command and return its answer; a refusal or silence is a :class:`PtuError`."""
        if self._stale:
            self._settle()
            self._stale = False
        self._events.extend(self._read_available(wait=False))  # unprompted events since the last command
        self._drain_unprompted()
        try:
            self._serial.write(command(name, value))
        except (serial.SerialException, OSError) as exc:
            raise PtuError(name, f"cannot write to {self.port}: {exc}") from exc
        reply = self._await_reply(name, self._reply_timeout_s if timeout_s is None else timeout_s)
        if not reply.ok:
            raise PtuError(name, f"refused by the unit: {reply.text or '(no message)'}")
        return reply

    def close(self) -> None:
        self._serial.close()

    def _settle(self) -> None:
        """After an answer that did not come in time: discard what arrives until the line has been quiet
        for a reply's timeout, then flush. Flushing at once left a late answer on its way, and the next
        command took it for its own (a pan position read as the tilt's)."""
        now = time.monotonic()
        quiet_until, give_up = now + self._reply_timeout_s, now + 5 * self._reply_timeout_s  # not a chatterer
        while time.monotonic() < min(quiet_until, give_up):
            if self._read_available():
                quiet_until = time.monotonic() + self._reply_timeout_s
        self.flush()

    def _await_reply(self, name: str, timeout_s: float) -> Reply:
        deadline = time.monotonic() + timeout_s
        while True:
            while self._events:
                event = self._events.popleft()
                if isinstance(event, Reply):
                    return event
                self._note(event)
            if time.monotonic() >= deadline:
                self._stale = True
                raise PtuError(name, f"no answer from the unit on {self.port} within {timeout_s:g} s")
            self._events.extend(self._read_available())

    def _drain_unprompted(self) -> None:
        while self._events:
            event = self._events.popleft()
            if isinstance(event, Reply):
                log.warning("PTU: an answer nobody waited for: %s", event)
            else:
                self._note(event)

    def _note(self, event: Event) -> None:
        if isinstance(event, LimitHit):
            log.warning("PTU: the %s axis hit its limit", event.axis)
            self.limit_hits.append(event.axis)
        elif isinstance(event, Noise):
            log.debug("PTU: %s", event.text)

    def _read_available(self, wait: bool = True) -> list[Event]:
        """What has arrived; with ``wait``, the first byte is awaited for up to the read timeout."""
        try:
            waiting = self._serial.in_waiting
            data = self._serial.read(max(1, waiting)) if waiting or wait else b""
        except (serial.SerialException, OSError) as exc:
            raise PtuError("read", f"cannot read from {self.port}: {exc}") from exc
        return self._tokenizer.feed(data)


def wake(link: PtuLink, startup_timeout_s: float) -> None:
    """Repeat ``ED`` until the unit answers (it ignores input while self-calibrating), then flush."""
    deadline = time.monotonic() + startup_timeout_s
    while True:
        try:
            link.transact("ED")
            break
        except PtuError as exc:
            if time.monotonic() >= deadline:
                raise PtuError("ED", f"the unit on {link.port} did not answer within {startup_timeout_s:g} s "
                                     "(powered? right port? 9600 baud?)") from exc
    link.flush()


def probe(port: str, baud: int = 9600, timeout_s: float = 2.0) -> dict:
    """Identify a PTU on ``port``: ``{"device": "ptu-d46", "port": ..., "version": ...}``."""
    link = PtuLink(port, baud, min(timeout_s, 0.5))
    try:
        wake(link, timeout_s)
        link.transact("FT")
        version = link.transact("V").text
    finally:
        link.close()
    return {"device": "ptu-d46", "port": port, "version": version}


class PtuPanTilt:
    """``PanTilt`` over a PTU-D46; angles in radians, the unit's positions only inside."""

    def __init__(self, config: PtuConfig, limits: PanTiltLimits = PanTiltLimits()):
        self.config = config
        self._link = PtuLink(config.port, config.baud, config.reply_timeout_s)
        self._io = threading.Lock()  # one command/answer at a time
        self._halt = threading.Event()
        self._closed = False
        try:
            with self._io:
                self._initialise(limits)
        except BaseException:
            self._link.close()
            raise

    def _initialise(self, configured: PanTiltLimits) -> None:
        wake(self._link, self.config.startup_timeout_s)
        for mode in ("FT", "LE", "I"):
            self._link.transact(mode)
        self._res = {axis: parse_decimal(self._link.transact(name), name)
                     for axis, name in (("P", "PR"), ("T", "TR"))}
        for axis, name in (("P", "PR"), ("T", "TR")):
            if not self._res[axis] > 0.0:  # every conversion divides by it
                raise PtuError(name, f"the unit reports a resolution of {self._res[axis]:g} arc-seconds a position")
        self._range = {name: parse_integer(self._link.transact(name), name) for name in ("PN", "PX", "TN", "TX")}
        self.limits = self._intersect(configured)
        self._set_slew(configured.pan_speed_deg_s, configured.tilt_speed_deg_s, configured.accel_deg_s2)
        self._state = self._query_positions() + (False,)
        log.info("PTU-D46 on %s: %.4f/%.4f arcsec per position, limits %s", self.config.port,
                 self._res["P"], self._res["T"], self.limits)

    def _set_slew(self, pan_deg_s: float, tilt_deg_s: float, accel_deg_s2: float) -> None:
        for name, value in (("PS", pan_deg_s), ("TS", tilt_deg_s), ("PA", accel_deg_s2), ("TA", accel_deg_s2)):
            self._link.transact(name, max(1, round(deg_to_positions(value, self._res[name[0]]))))
        self.limits = replace(self.limits, pan_speed_deg_s=pan_deg_s, tilt_speed_deg_s=tilt_deg_s,
                              accel_deg_s2=accel_deg_s2)

    def _intersect(self, configured: PanTiltLimits) -> PanTiltLimits:
        r = self._range
        deg = {name: r[name] * self._res[name[0]] / 3600.0 for name in r}
        limits = replace(configured, pan_min_deg=max(configured.pan_min_deg, deg["PN"]),
                         pan_max_deg=min(configured.pan_max_deg, deg["PX"]),
                         tilt_min_deg=max(configured.tilt_min_deg, deg["TN"]),
                         tilt_max_deg=min(configured.tilt_max_deg, deg["TX"]))
        if limits.pan_min_deg > limits.pan_max_deg or limits.tilt_min_deg > limits.tilt_max_deg:
            raise PtuError("PN", f"the unit's limits {r} leave nothing of the configured ones {configured}")
        return limits

    # ------------------------------------------------------------------------- PanTilt

    def look(self, pan_rad: float, tilt_rad: float, cancel: threading.Event) -> float:
        """Slew to ``(pan, tilt)`` and wait until both axes are there, then settle."""
        self._halt.clear()
        start = time.monotonic()
        goal = (self._to_positions(pan_rad, "P"), self._to_positions(tilt_rad, "T"))
        if goal == self._state[:2]:
            return 0.0  # already there: nothing moves, nothing to settle
        # the slew the speeds give, and the timeout beyond it: a slow head's long sweep is not a failure
        expected_s = self.limits.slew_time_s(*(math.degrees(positions_to_rad(g - p, self._res[axis]))
                                                for g, p, axis in zip(goal, self._state[:2], "PT")))
        if cancel.is_set():  # a stop overtook the look: it never began (LookResult)
            return 0.0
        with self._io:
            self._check_open("look")
            self._link.limit_hits.clear()
            self._link.transact("PP", goal[0])
            self._link.transact("TP", goal[1])
        deadline = start + expected_s + self.config.move_timeout_s
        while True:
            with self._io:
                self._check_open("look")
                positions = self._query_positions()
                arrived = positions == goal
                self._state = positions + (not arrived,)
                hits = list(self._link.limit_hits)
            if hits:
                self.halt()
                raise PtuError("look", f"the {' and '.join(hits)} axis hit its limit (!{hits[0][0].upper()}) "
                                       f"on the way to {math.degrees(pan_rad):.2f}°, {math.degrees(tilt_rad):.2f}°")
            if arrived:
                cancel.wait(self.limits.settle_s)
                break
            if cancel.is_set() or self._halt.is_set():
                self.halt()
                break
            if time.monotonic() >= deadline:
                self.halt()
                raise PtuError("look", f"the head did not reach its goal within {expected_s:.2f} s of slewing "
                                       f"and {self.config.move_timeout_s:g} s more")
            cancel.wait(self.config.poll_s)
        return time.monotonic() - start

    def set_speed(self, pan_deg_s: float, tilt_deg_s: float) -> None:
        """Slew speeds of the next looks (``PS``/``TS``); ``limits`` follows, for the time model."""
        with self._io:
            self._check_open("set_speed")
            self._set_slew(pan_deg_s, tilt_deg_s, self.limits.accel_deg_s2)

    def halt(self) -> None:
        """Stop both axes at once (``H``); safe from any thread."""
        self._halt.set()
        with self._io:
            if self._closed:
                return
            self._link.transact("H")
            self._state = self._query_positions() + (False,)

    def reading(self) -> PanTiltReading:
        pan, tilt, moving = self._state
        return PanTiltReading(positions_to_rad(pan, self._res["P"]), positions_to_rad(tilt, self._res["T"]), moving)

    def close(self) -> None:
        """Halt, then release the port; a second call does nothing."""
        if self._closed:
            return
        try:
            self.halt()
        except PtuError as exc:
            log.warning("PTU: halt on close failed: %s", exc)
        finally:
            with self._io:
                self._closed = True
                self._link.close()

    # ------------------------------------------------------------------------- helpers

    def _check_open(self, name: str) -> None:
        if self._closed:
            raise PtuError(name, "the pan-tilt unit was closed")

    def _to_positions(self, angle_rad: float, axis: str) -> int:
        """The nearest position, kept inside the unit's range (rounding may step just past it)."""
        lo, hi = self._range[axis + "N"], self._range[axis + "X"]
        return min(max(rad_to_positions(angle_rad, self._res[axis]), lo), hi)

    def _query_positions(self) -> tuple[int, int]:
        return parse_integer(self._link.transact("PP"), "PP"), parse_integer(self._link.transact("TP"), "TP")
