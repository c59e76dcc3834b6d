"""A Pioneer 3 base over ARCOS (RS-232, or TCP to the vendor's simulators): the ``Base`` protocol.

Threads, and why each exists:
- the *link* thread reads the port, parses SIPs (every 100 ms) into the latest status, sends PULSE
  when nothing else was sent (the robot halts after 2 s of silence), notices a dead link (no SIP
  for ``link_timeout_ms``, or a serial error) and then reconnects by itself;
- ``move`` runs in the caller's thread (the agent's base worker), closed on SIP odometry;
- ``stop`` writes from any thread at once; a halted move cannot write a motion command after it.

While the link is down ``reading`` and ``move`` raise :class:`DeviceFault`, which the agent
answers with an error of code ``device``. Odometry continues across a reconnection: the robot
restarts its own at zero when a session opens, and the driver carries on from the last pose.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass

import serial

from onboard.config import PioneerConfig
from onboard.devices import BaseReading, DeviceFault, MotionOutcome
from onboard.hardware import arcos
from onboard.hardware.arcos import ArcosError, Command, Packet, PacketReader, RobotIdentity
from shared.geometry import Pose2D, wrap_angle
from shared.limits import BaseLimits

log = logging.getLogger(__name__)

_SYNCS = (Command.SYNC0, Command.SYNC1, Command.SYNC2)
_HEAD_WITHIN_RAD = math.radians(100.0)  # the firmware's heading control finishes the last part of a turn
_STILL_RAD_S = math.radians(2.0)
_STILL_M_S = 0.01
_MIN_DRIVE_M_S = 0.05  # the slowest approach speed: slower crawls for nothing
_SIP_PERIOD_S = 0.1
_BRAKING_MARGIN = 0.8  # plan to brake at 80 % of the deceleration the firmware was given


@dataclass(frozen=True)
class _Status:
    """What the latest SIP said, in the driver's terms."""

    seq: int
    received_s: float
    pose: Pose2D  # odometry in the agent's frame
    local_heading_rad: float  # the robot's own THPOS heading, which HEAD takes
    heading_total_rad: float  # unwrapped: turns are measured on it
    speed_m_s: float
    turn_rate_rad_s: float
    moving: bool
    stalled: bool
    motors_enabled: bool
    battery_v: float


@dataclass
class WireTimes:
    """``time.perf_counter`` stamps for the benchmark: a call and the first bytes it caused."""

    move_called_s: float | None = None
    move_wire_s: float | None = None  # first VEL, RVEL or HEAD of that move written
    stop_called_s: float | None = None
    stop_wire_s: float | None = None  # VEL 0 written


class PioneerBase:
    """The ``Base`` protocol over ARCOS. Connects in the constructor (``DeviceFault`` if nothing answers)."""

    def __init__(self, config: PioneerConfig, limits: BaseLimits, start: Pose2D = Pose2D(0.0, 0.0, 0.0)):
        if config.port == "sim":
            raise ValueError("PioneerConfig.port is 'sim': use the simulated base instead of PioneerBase")
        self.config = config
        self.limits = limits
        self.identity: RobotIdentity | None = None
        self.wire_times = WireTimes()
        self._write_lock = threading.Lock()
        self._port: serial.SerialBase | None = None
        self._last_write_s = 0.0
        self._halted = False  # set by stop, cleared by move: no motion command is written while set
        self._motion_lock = threading.Lock()
        self._status_changed = threading.Condition()
        self._status: _Status | None = None
        self._fault: str | None = None
        self._closing = threading.Event()
        self._continue_from = start
        self._session: _Session | None = None
        self._port, self._session = self._connect()
        self._thread = threading.Thread(target=self._link_loop, name="pioneer-link", daemon=True)
        self._thread.start()

    # --- the Base protocol ---------------------------------------------------------------------------

    def reading(self) -> BaseReading:
        s = self._current()
        return BaseReading(s.pose, s.speed_m_s, s.turn_rate_rad_s, s.moving, s.stalled)

    def move(self, turn_rad: float, distance_m: float, speed_m_s: float,
             cancel: threading.Event) -> MotionOutcome:
        """Turn in place, then drive straight, both closed on SIP odometry."""
        self.wire_times.move_called_s, self.wire_times.move_wire_s = time.perf_counter(), None
        with self._motion_lock:
            self._current()  # refused at once while the link is down
            with self._write_lock:  # a stop from now on either finds the cancel set here or halts the writes
                if cancel.is_set():  # stopped before it began: not one motion command goes out
                    return MotionOutcome("stopped", 0.0, 0.0)
                self._halted = False
            self._ensure_enabled(cancel)
            started = time.monotonic()
            try:
                status = self._turn(turn_rad, cancel) if turn_rad else "done"
                driven = 0.0
                if status == "done" and distance_m:
                    status, driven = self._drive(distance_m, speed_m_s, cancel)
            except BaseException:
                self._halt()
                raise
            if status != "done":  # stopped, or stalled: the last RVEL or VEL would push on (PULSE feeds the watchdog)
                self._halt()
            # odometry can creep back a few millimetres at a stall; the distance driven is never negative
            return MotionOutcome(status, max(0.0, driven), time.monotonic() - started)

    def stop(self) -> None:
        """VEL 0 and RVEL 0 at once, from any thread; a running move ends as ``stopped``."""
        self.wire_times.stop_called_s, self.wire_times.stop_wire_s = time.perf_counter(), None
        self._halt(stamped=True)

    def _halt(self, stamped: bool = False) -> None:
        """VEL 0 and RVEL 0; ``stamped`` (a caller's stop, not a move's own) times the VEL 0 for the benchmark."""
        with self._write_lock:
            self._halted = True
            try:
                self._write_locked(arcos.build_packet(Command.VEL, 0))
                if stamped:
                    self.wire_times.stop_wire_s = time.perf_counter()
                self._write_locked(arcos.build_packet(Command.RVEL, 0))
            except (DeviceFault, serial.SerialException, OSError) as exc:
                log.warning("Pioneer: stop not sent (%s); the robot's watchdog halts it within 2 s", exc)
        with self._status_changed:
            self._status_changed.notify_all()

    def close(self) -> None:
        """Stop, disable the motors, end the session and release the port, whatever happens."""
        try:
            self.stop()
        finally:
            self._closing.set()
            self._thread.join(timeout=5.0)
            with self._write_lock:
                port, self._port = self._port, None
            if port is not None:
                try:
                    if self._fault is None:
                        _send_goodbye(port)
                finally:
                    port.close()
            log.info("Pioneer on %s closed", self.config.port)

    # --- motion --------------------------------------------------------------------------------------

    def _turn(self, turn_rad: float, cancel: threading.Event) -> str:
        first = self._current()
        goal = first.heading_total_rad + turn_rad
        deadline = time.monotonic() + self.limits.turn_time_s(turn_rad) + self.config.motion_timeout_margin_s
        tolerance = math.radians(self.config.turn_tolerance_deg)
        rate = math.radians(self.limits.default_turn_rate_deg_s)
        sent: tuple[int, int] | None = None
        sent_s = 0.0
        status = first
        while True:
            left = goal - status.heading_total_rad
            if abs(left) < tolerance and abs(status.turn_rate_rad_s) < _STILL_RAD_S:
                return "done"
            if status.stalled:
                return "stalled"
            if abs(left) > _HEAD_WITHIN_RAD:
                command = (Command.RVEL, round(math.degrees(math.copysign(rate, left))))
            else:
                command = (Command.HEAD, round(math.degrees(status.local_heading_rad + left)) % 360)
            if command != sent or time.monotonic() - sent_s > self.config.resend_period_ms / 1000.0:
                self._send_motion(*command)
                sent, sent_s = command, time.monotonic()
            status = self._next_status(status, cancel, deadline, "turn")
            if status is None:
                return "stopped"

    def _drive(self, distance_m: float, speed_m_s: float, cancel: threading.Event) -> tuple[str, float]:
        first = self._current()
        sign, origin = math.copysign(1.0, distance_m), first.pose
        along = (math.cos(origin.heading_rad), math.sin(origin.heading_rad))
        decel = _BRAKING_MARGIN * self.limits.accel_m_s2
        deadline = (time.monotonic() + self.limits.drive_time_s(distance_m, speed_m_s)
                    + self.config.motion_timeout_margin_s)
        sent: int | None = None
        sent_s, braking = 0.0, False
        status = first
        while True:
            driven = sign * ((status.pose.x_m - origin.x_m) * along[0] + (status.pose.y_m - origin.y_m) * along[1])
            if status.stalled:
                return "stalled", driven
            if braking and sent == 0 and abs(status.speed_m_s) < _STILL_M_S:
                return "done", driven
            speed = abs(status.speed_m_s)
            left = abs(distance_m) - driven - speed * (time.monotonic() - status.received_s)
            # Brake where the firmware's deceleration stops the robot on the goal; the next SIP comes
            # a period later, so brake now if the goal would be half a period nearer than that.
            stopping_m = speed * speed / (2.0 * self.limits.accel_m_s2) + 0.5 * speed * _SIP_PERIOD_S
            braking = braking or left <= max(0.5 * self.config.drive_tolerance_m, stopping_m)
            wanted = 0.0 if braking else min(speed_m_s, max(_MIN_DRIVE_M_S, math.sqrt(2.0 * decel * left)))
            command = round(sign * wanted * 1000.0)
            changed = sent is None or (command != sent and (command == 0 or abs(command - sent) >= 10))
            if changed or time.monotonic() - sent_s > self.config.resend_period_ms / 1000.0:
                self._send_motion(Command.VEL, command)
                sent, sent_s = command, time.monotonic()
            status = self._next_status(status, cancel, deadline, "drive")
            if status is None:
                return "stopped", driven

    def _ensure_enabled(self, cancel: threading.Event) -> None:
        """Motors off (the robot's motor button, an e-stop): ask once more, refuse if they stay off."""
        status: _Status | None = self._current()
        if status.motors_enabled:
            return
        self._send_motion(Command.ENABLE, 1)
        deadline = time.monotonic() + 5 * _SIP_PERIOD_S
        while status is not None and not status.motors_enabled:
            if time.monotonic() > deadline:
                raise DeviceFault(f"Pioneer on {self.config.port}: the motors stay disabled (motor button or e-stop?)")
            status = self._next_status(status, cancel, deadline + 1.0, "motor enabling")

    def _next_status(self, after: _Status, cancel: threading.Event, deadline: float, what: str) -> _Status | None:
        """The next SIP's status; None if the motion was cancelled or stopped."""
        with self._status_changed:
            while True:
                if cancel.is_set() or self._halted:
                    return None
                status = self._current()
                if status.seq != after.seq:
                    return status
                if time.monotonic() > deadline:
                    raise DeviceFault(f"Pioneer on {self.config.port}: the {what} did not finish in time")
                self._status_changed.wait(0.02)  # cancel is an Event: look at it often

    def _send_motion(self, command: Command, value: int) -> None:
        """A motion command, unless a stop came first."""
        with self._write_lock:
            if self._halted:
                return
            self._write_locked(arcos.build_packet(command, value))
            if self.wire_times.move_wire_s is None:
                self.wire_times.move_wire_s = time.perf_counter()

    # --- status --------------------------------------------------------------------------------------

    def _current(self) -> _Status:
        fault, status = self._fault, self._status
        if fault is not None:
            raise DeviceFault(f"Pioneer on {self.config.port}: {fault}; reconnecting")
        if status is None:
            raise DeviceFault(f"Pioneer on {self.config.port}: no status received yet")
        return status

    def _on_sip(self, sip: arcos.Sip, session: _Session) -> None:
        pose, heading_total = session.pose(sip)
        previous = self._status
        status = _Status(previous.seq + 1 if previous else 0, time.monotonic(), pose, sip.theta_rad, heading_total,
                         sip.speed_mm_s / 1000.0, sip.turn_rate_rad_s, sip.moving, sip.stalled,
                         sip.motors_enabled, sip.battery_v)
        with self._status_changed:
            self._status = status
            self._continue_from = pose
            self._status_changed.notify_all()

    # --- the link ------------------------------------------------------------------------------------

    def _write_locked(self, packet: bytes) -> None:
        """Write one packet (the write lock held), keeping ARCOS's gap between commands."""
        port = self._port
        if port is None or self._fault is not None:
            raise DeviceFault(f"Pioneer on {self.config.port}: link down")
        gap = self.config.command_gap_ms / 1000.0 - (time.monotonic() - self._last_write_s)
        if gap > 0:
            time.sleep(gap)
        port.write(packet)
        self._last_write_s = time.monotonic()

    def _connect(self) -> tuple[serial.SerialBase, _Session]:
        """Open the port, sync (:func:`handshake`, which begins with a STOP), OPEN, stop whatever the
        robot resumes, ENABLE, set the limits."""
        c = self.config
        try:
            port = serial.serial_for_url(c.port, baudrate=c.baud, timeout=0.02, write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceFault(f"Pioneer on {c.port}: cannot open the port: {exc}") from None
        try:
            self.identity = handshake(port, c, self._closing)
            session = _Session(arcos.dist_conv_factor(self.identity.subtype), self._continue_from)
            port.write(arcos.build_packet(Command.OPEN, 1))
            first = _wait_for(port, PacketReader(), lambda p: p.id in arcos.SIP_TYPES, c.link_timeout_ms / 1000.0)
            if first is None:
                raise DeviceFault(f"Pioneer on {c.port}: no status packet after OPEN")
            for packet in self._setup_packets():  # first: OPEN may have resumed the robot's last motion
                port.write(packet)
                time.sleep(c.command_gap_ms / 1000.0)
            sip = arcos.parse_sip(first)
        except (serial.SerialException, OSError, ArcosError) as exc:
            port.close()
            raise DeviceFault(f"Pioneer on {c.port}: while connecting: {exc}") from None
        except BaseException:
            port.close()
            raise
        self._last_write_s = time.monotonic()
        log.info("Pioneer on %s: %s %s %s connected", c.port, self.identity.name, self.identity.type,
                 self.identity.subtype)
        self._on_sip(sip, session)
        return port, session

    def _setup_packets(self) -> list[bytes]:
        """Stop (a Pioneer resumes its last motion when talked to again), enable, and the limits."""
        lim = self.limits
        values = [(Command.VEL, 0), (Command.RVEL, 0), (Command.ENABLE, 1),
                  (Command.SETV, round(lim.max_speed_m_s * 1000)), (Command.SETA, round(lim.accel_m_s2 * 1000)),
                  (Command.SETA, -round(lim.accel_m_s2 * 1000)), (Command.SETRV, round(lim.default_turn_rate_deg_s)),
                  (Command.SETRA, round(lim.turn_accel_deg_s2)), (Command.SETRA, -round(lim.turn_accel_deg_s2))]
        return [arcos.build_packet(command, value) for command, value in values]

    def _link_loop(self) -> None:
        reader = PacketReader()
        while not self._closing.is_set():
            if self._fault is not None:
                self._reconnect(reader)
                continue
            try:
                self._serve_link(reader)
            except (serial.SerialException, OSError) as exc:
                self._lose_link(f"serial error: {exc}")

    def _serve_link(self, reader: PacketReader) -> None:
        port, session = self._port, self._session
        data = port.read(max(1, port.in_waiting))
        now = time.monotonic()
        for packet in reader.feed(data):
            if packet.id in arcos.SIP_TYPES:
                try:
                    self._on_sip(arcos.parse_sip(packet), session)
                except ArcosError as exc:
                    log.warning("Pioneer: bad status packet ignored: %s", exc)
        status = self._status
        if status is not None and now - status.received_s > self.config.link_timeout_ms / 1000.0:
            self._lose_link(f"no status packet for {1000 * (now - status.received_s):.0f} ms")
            return
        with self._write_lock:
            if now - self._last_write_s > self.config.pulse_period_ms / 1000.0 and self._fault is None:
                self._write_locked(arcos.build_packet(Command.PULSE))

    def _lose_link(self, why: str) -> None:
        """Refuse motion until the link is back. The robot may still hear us when it has gone silent,
        and the SYNC0 of every reconnection attempt is a PULSE that feeds its watchdog, so it is told
        to stop first: else it would drive on with its last motion command."""
        log.error("Pioneer on %s: link down (%s); motion refused until it reconnects", self.config.port, why)
        with self._write_lock:
            try:
                self._write_locked(arcos.build_packet(Command.STOP))
            except (DeviceFault, serial.SerialException, OSError):
                pass  # the robot's watchdog is what is left
            self._fault = why
            port, self._port = self._port, None
        with self._status_changed:
            self._status_changed.notify_all()
        if port is not None:
            try:
                port.close()
            except (serial.SerialException, OSError):
                pass

    def _reconnect(self, reader: PacketReader) -> None:
        if self._closing.wait(self.config.reconnect_period_ms / 1000.0):
            return
        try:
            port, session = self._connect()
        except DeviceFault as exc:
            log.info("Pioneer: reconnection failed: %s", exc)
            return
        if self._closing.is_set():
            port.close()
            return
        reader.clear()
        with self._write_lock:
            self._port, self._session, self._fault = port, session, None
        log.info("Pioneer on %s: link back", self.config.port)


class _Session:
    """One ARCOS session's odometry: raw SIP positions into the agent's frame, continuous across
    wraps and across sessions (the robot restarts its odometry at zero on OPEN)."""

    def __init__(self, dist_conv_factor: float, continue_from: Pose2D):
        self._unwrap = arcos.OdometryUnwrapper(dist_conv_factor)
        self._continue_from = continue_from
        self._origin: Pose2D | None = None
        self._last_heading: float | None = None
        self._heading_total = continue_from.heading_rad

    def pose(self, sip: arcos.Sip) -> tuple[Pose2D, float]:
        """(odometry pose, unwrapped heading) of one SIP."""
        x_mm, y_mm = self._unwrap.update(sip.x_raw, sip.y_raw)
        local = Pose2D(x_mm / 1000.0, y_mm / 1000.0, sip.theta_rad)
        if self._origin is None:
            self._origin = self._continue_from.compose(local.inverse())
        if self._last_heading is not None:
            self._heading_total += wrap_angle(sip.theta_rad - self._last_heading)
        self._last_heading = sip.theta_rad
        return self._origin.compose(local), self._heading_total


def _wait_for(port: serial.SerialBase, reader: PacketReader, wanted, timeout_s: float) -> Packet | None:
    """The first packet for which ``wanted`` is true, or None after ``timeout_s``; others are dropped."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for packet in reader.feed(port.read(max(1, port.in_waiting))):
            if wanted(packet):
                return packet
    return None


def handshake(port: serial.SerialBase, config: PioneerConfig,
              give_up: threading.Event | None = None) -> RobotIdentity:
    """STOP, then SYNC0, SYNC1, SYNC2 with retries; an old session still open is closed first. The
    STOP is for a robot whose session is still open, its status lost on the way back: it hears the
    SYNC0s, which it takes as PULSEs, and would drive on with its last command."""
    port.write(arcos.build_packet(Command.STOP))
    time.sleep(config.command_gap_ms / 1000.0)
    reader, timeout_s = PacketReader(), config.sync_reply_timeout_ms / 1000.0
    for attempt in range(config.sync_attempts):
        if give_up is not None and give_up.is_set():
            break
        port.reset_input_buffer()
        reader.clear()
        step = 0
        while step < len(_SYNCS):
            port.write(arcos.build_packet(_SYNCS[step]))
            reply = _wait_for(port, reader, lambda p: True, timeout_s)
            if reply is None:
                log.info("Pioneer on %s: no reply to SYNC%d (attempt %d)", config.port, step, attempt + 1)
                break
            if reply.id in arcos.SIP_TYPES:
                log.warning("Pioneer on %s: an old session is still open; closing it", config.port)
                port.write(arcos.build_packet(Command.CLOSE, 1))
                time.sleep(config.stale_session_wait_ms / 1000.0)
                break
            if reply.id != _SYNCS[step]:
                # out of step: start again at SYNC0, as ARIA does, but as a new attempt: a device that
                # answers everything with some other packet once kept this loop going for good
                log.info("Pioneer on %s: packet 0x%02x in reply to SYNC%d (attempt %d)", config.port, reply.id,
                         step, attempt + 1)
                break
            if step == 2:
                try:
                    return arcos.parse_sync2(reply.payload)
                except ArcosError as exc:
                    raise DeviceFault(f"Pioneer on {config.port}: {exc}") from None
            step += 1
    raise DeviceFault(f"Pioneer on {config.port}: no ARCOS robot answered SYNC0/1/2 "
                      f"({config.sync_attempts} attempts, {config.sync_reply_timeout_ms} ms each)")


def _send_goodbye(port: serial.SerialBase) -> None:
    """ENABLE 0, then CLOSE, as ARIA disconnects."""
    port.write(arcos.build_packet(Command.ENABLE, 0))
    time.sleep(0.1)
    port.write(arcos.build_packet(Command.CLOSE, 1))
    port.flush()


def probe(port: str, baud: int = 9600, timeout_ms: int = 1000) -> dict:
    """Identify a Pioneer on ``port`` (a device path or a URL) from its SYNC2 reply, without opening
    a session. ``DeviceFault`` if nothing answers like one. The robot is left stopped: the handshake
    begins with a STOP, and a robot whose agent died with its session open may have been woken by the
    SYNC0s all the same (it takes them as PULSEs), so one more STOP ends the probe."""
    config = PioneerConfig(port=port, baud=baud, sync_reply_timeout_ms=timeout_ms, sync_attempts=2)
    try:
        link = serial.serial_for_url(port, baudrate=baud, timeout=0.02, write_timeout=1.0)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise DeviceFault(f"cannot open {port}: {exc}") from None
    try:
        identity = handshake(link, config)
    finally:
        try:
            link.write(arcos.build_packet(Command.STOP))
            link.flush()
        except (serial.SerialException, OSError):  # the port failed: the handshake's error says so
            pass
        link.close()
    return {"device": "pioneer", "name": identity.name, "type": identity.type, "subtype": identity.subtype}
