"""A Pioneer 3 base as an ARCOS server on a pseudo-terminal, moving the simulator's physics.

:class:`PioneerServerState` is the robot's firmware, pure: it consumes packets and the time and
produces reply bytes, and drives a velocity-controlled plant (``SimBase.step_velocity``). It does
what ARIA expects of a robot (read from AriaCoda's source): it tolerates ``WMS2\\r``, echoes
SYNC0/1/2, answers SYNC2 with name, type and subtype, sends no SIP before OPEN, takes OPEN and
CLOSE bare or with an argument, ignores CONFIG (ARIA carries on without a config packet after 1 s;
a half-filled one would mislead it) and HOSTBAUD (a pseudo-terminal has no baud rate), sends a SIP
every 100 ms, and has the real robot's watchdog: with no command for 2 s it halts, and the last
motion resumes when commands come back.

:class:`PioneerEmulator` serves that state on a :class:`PseudoTerminal` in real time, because a
real driver talks to it.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Protocol

from onboard.devices import BaseReading
from onboard.emulators.cable import Cable
from onboard.emulators.pty import PseudoTerminal
from onboard.emulators.tcp import TcpPort
from onboard.hardware import arcos
from onboard.hardware.arcos import ArcosError, Command, Packet
from shared.geometry import Pose2D, wrap_angle
from shared.strict import bounds

log = logging.getLogger(__name__)

PHYSICS_STEP_S = 0.02
# Firmware limits of a P3-DX (its Operations Manual), and the firmware's defaults until the client sets its own.
MAX_SPEED_MM_S = 2200
MAX_TURN_RATE_DEG_S = 500
_SETTLE_GAIN_PER_S = 4.0  # position and heading goals are approached exponentially at the end
_BRAKING_MARGIN = 0.8  # plan to brake at 80 % of the deceleration, so a step's lag does not overshoot
_HEADING_DONE_RAD = math.radians(0.2)
_DISTANCE_DONE_MM = 1.0


@dataclass(frozen=True)
class PioneerEmulatorConfig:
    """What the emulated robot says it is, and its timing."""

    name: str = "Pioneer"
    type: str = "Pioneer"
    subtype: str = "p3dx"  # the older controller and the vendor's simulators; "p3dx-sh" for an SH one
    sip_period_s: float = field(default=0.1, metadata=bounds(0.01, 1.0))
    watchdog_s: float = field(default=2.0, metadata=bounds(0.1, 60.0))  # halt after this long without a command
    battery_v: float = field(default=12.8, metadata=bounds(0.0, 25.5))

    def __post_init__(self) -> None:
        arcos.dist_conv_factor(self.subtype)  # an unknown robot is refused at once


class VelocityPlant(Protocol):
    """The physics the firmware drives (``onboard.sim.base.SimBase``)."""

    def step_velocity(self, speed_m_s: float, turn_rate_rad_s: float, dt_s: float) -> bool: ...

    def reading(self) -> BaseReading: ...


@dataclass
class _Motion:
    """The firmware's motion state: what it was told and how fast it goes now."""

    enabled: bool = False
    speed_max_mm_s: float = 750.0
    accel_mm_s2: float = 300.0
    decel_mm_s2: float = 300.0
    turn_max_deg_s: float = 300.0
    turn_accel_deg_s2: float = 100.0
    turn_decel_deg_s2: float = 100.0
    speed_goal_mm_s: float = 0.0  # VEL
    distance_left_mm: float | None = None  # MOVE, instead of VEL
    turn_goal_deg_s: float = 0.0  # RVEL, ROTATE
    heading_goal_rad: float | None = None  # HEAD, DHEAD, instead of RVEL
    speed_mm_s: float = 0.0
    turn_deg_s: float = 0.0
    stalled: bool = False


class PioneerServerState:
    """The firmware: packets and time in, reply bytes out."""

    def __init__(self, plant: VelocityPlant, config: PioneerEmulatorConfig = PioneerEmulatorConfig()):
        self.config = config
        self._plant = plant
        self._conv = arcos.dist_conv_factor(config.subtype)
        self._identity = arcos.RobotIdentity(config.name, config.type, config.subtype)
        self._sync_step = 0  # SYNC0, SYNC1, SYNC2 seen in order
        self.open = False
        self.motion = _Motion()
        self._origin = plant.reading().pose  # odometry is reported from where OPEN or SETO happened
        self._last_command_s = 0.0
        self._last_step_s: float | None = None
        self._next_sip_s = 0.0
        self.watchdog_tripped = False
        self.history: deque[tuple[int, int | str | None]] = deque(maxlen=64)  # recent commands, for tests and logs

    # --- packets in ----------------------------------------------------------------------------------

    def receive(self, packet: Packet, now_s: float) -> list[bytes]:
        """Handle one client packet; return what to send back."""
        try:
            arg = arcos.parse_arg(packet.payload)
        except ArcosError as exc:
            log.warning("ignoring command %d: %s", packet.id, exc)
            return []
        self.history.append((packet.id, arg))
        if not self.open:
            return self._handshake(packet.id, arg, now_s)
        self._last_command_s = now_s
        if self.watchdog_tripped:
            log.info("commands are back: resuming the last motion")
            self.watchdog_tripped = False
        self._command(packet.id, arg)
        return []

    def _handshake(self, command: int, arg: int | str | None, now_s: float) -> list[bytes]:
        if command == Command.OPEN and self._sync_step == 3:  # OPEN and SYNC1 share a number
            self._open(now_s)
            return []
        if command == Command.SYNC0:
            self._sync_step = 1
            return [arcos.build_packet(Command.SYNC0)]
        if command == Command.SYNC1 and self._sync_step == 1:
            self._sync_step = 2
            return [arcos.build_packet(Command.SYNC1)]
        if command == Command.SYNC2 and self._sync_step == 2:
            self._sync_step = 3
            return [arcos.frame(bytes((Command.SYNC2,)) + arcos.encode_sync2(self._identity))]
        if command in (Command.SYNC1, Command.SYNC2):
            self._sync_step = 0  # out of order: the client starts again at SYNC0
        return []

    def _open(self, now_s: float) -> None:
        log.info("session opened")
        self.open, self.motion = True, _Motion()
        self._origin = self._plant.reading().pose
        self._last_command_s, self._next_sip_s = now_s, now_s
        self.watchdog_tripped = False

    def _close(self) -> None:
        log.info("session closed")
        self.open, self._sync_step, self.motion = False, 0, _Motion()

    def _command(self, command: int, arg: int | str | None) -> None:
        m, value = self.motion, arg if isinstance(arg, int) else 0
        if command == Command.CLOSE:
            self._close()
        elif command == Command.ENABLE:
            m.enabled = bool(value)
            if not m.enabled:
                self._halt_goals()
                m.speed_mm_s = m.turn_deg_s = 0.0
        elif command == Command.SETO:
            self._origin = self._plant.reading().pose
        elif command in (Command.STOP, Command.E_STOP):
            self._halt_goals()
            if command == Command.E_STOP:
                m.speed_mm_s = m.turn_deg_s = 0.0
        elif command in _LIMIT_SETTERS:
            _LIMIT_SETTERS[command](m, value)
        elif command in _MOTION_COMMANDS:
            self._motion_command(command, value)
        # PULSE, OPEN, CONFIG, SONAR, BUMPSTALL, HOSTBAUD and unknown commands only feed the watchdog

    def _motion_command(self, command: int, value: int) -> None:
        m = self.motion
        if command == Command.VEL:
            m.speed_goal_mm_s, m.distance_left_mm = float(value), None
        elif command == Command.MOVE:
            m.distance_left_mm = float(value)
        elif command in (Command.RVEL, Command.ROTATE):
            m.turn_goal_deg_s, m.heading_goal_rad = float(value), None
        elif command == Command.HEAD:
            m.heading_goal_rad = wrap_angle(math.radians(value))
        elif command == Command.DHEAD:
            m.heading_goal_rad = wrap_angle(self.odometry().heading_rad + math.radians(value))
        elif command == Command.VEL2:
            word = value & 0xFFFF  # right wheel in the low byte, left in the high, 20 mm/s units
            right, left = (_signed_byte(word & 0xFF) * 20, _signed_byte(word >> 8) * 20)
            m.speed_goal_mm_s, m.distance_left_mm = 0.5 * (left + right), None
            m.turn_goal_deg_s = math.degrees(0.5 * (right - left) * arcos.DIFF_CONV_FACTOR)
            m.heading_goal_rad = None

    def _halt_goals(self) -> None:
        m = self.motion
        m.speed_goal_mm_s = m.turn_goal_deg_s = 0.0
        m.distance_left_mm = m.heading_goal_rad = None

    # --- time ----------------------------------------------------------------------------------------

    def step(self, now_s: float) -> list[bytes]:
        """Run the physics up to ``now_s``; return the SIPs that fell due."""
        if self._last_step_s is None:
            self._last_step_s = now_s
        if self.open and not self.watchdog_tripped and now_s - self._last_command_s > self.config.watchdog_s:
            log.warning("watchdog: no command for %.1f s, halting", now_s - self._last_command_s)
            self.watchdog_tripped = True
        while now_s - self._last_step_s > 1e-9:
            dt = min(PHYSICS_STEP_S, now_s - self._last_step_s)
            self._physics(dt)
            self._last_step_s += dt
        if not self.open or now_s < self._next_sip_s:
            return []
        self._next_sip_s = max(self._next_sip_s + self.config.sip_period_s, now_s - self.config.sip_period_s)
        return [arcos.encode_sip(self.sip())]

    def _physics(self, dt: float) -> None:
        m = self.motion
        live = self.open and m.enabled and not self.watchdog_tripped
        m.speed_mm_s = _ramp(m.speed_mm_s, self._speed_wanted() if live else 0.0, m.accel_mm_s2, m.decel_mm_s2, dt)
        m.turn_deg_s = _ramp(m.turn_deg_s, self._turn_wanted() if live else 0.0, m.turn_accel_deg_s2,
                             m.turn_decel_deg_s2, dt)
        if m.speed_mm_s == 0.0 and m.turn_deg_s == 0.0 and not self._plant.reading().moving:
            m.stalled = False
            return
        free = self._plant.step_velocity(m.speed_mm_s / 1000.0, math.radians(m.turn_deg_s), dt)
        m.stalled = not free
        if m.distance_left_mm is not None and free:
            m.distance_left_mm -= m.speed_mm_s * dt

    def _speed_wanted(self) -> float:
        m = self.motion
        if m.distance_left_mm is None:
            return max(-m.speed_max_mm_s, min(m.speed_max_mm_s, m.speed_goal_mm_s))
        if abs(m.distance_left_mm) < _DISTANCE_DONE_MM:
            return 0.0
        return _approach(m.distance_left_mm, m.speed_max_mm_s, m.decel_mm_s2)

    def _turn_wanted(self) -> float:
        m = self.motion
        if m.heading_goal_rad is None:
            return max(-m.turn_max_deg_s, min(m.turn_max_deg_s, m.turn_goal_deg_s))
        error = wrap_angle(m.heading_goal_rad - self.odometry().heading_rad)
        if abs(error) < _HEADING_DONE_RAD:
            return 0.0
        return _approach(math.degrees(error), m.turn_max_deg_s, m.turn_decel_deg_s2)

    # --- status out ----------------------------------------------------------------------------------

    def odometry(self) -> Pose2D:
        """The plant's odometry in the frame of the last OPEN or SETO."""
        return self._origin.inverse().compose(self._plant.reading().pose)

    def sip(self) -> arcos.Sip:
        m, pose = self.motion, self.odometry()
        half_diff = math.radians(m.turn_deg_s) / arcos.DIFF_CONV_FACTOR
        left, right = (0, 0) if m.stalled else (round(m.speed_mm_s - half_diff), round(m.speed_mm_s + half_diff))
        pushing = m.stalled and (m.speed_mm_s != 0.0 or m.turn_deg_s != 0.0)  # the wheels push, turning or driving
        control = m.heading_goal_rad if m.heading_goal_rad is not None else pose.heading_rad
        return arcos.Sip(moving=m.speed_mm_s != 0.0 or m.turn_deg_s != 0.0,
                         x_raw=round(pose.x_m * 1000.0 / self._conv), y_raw=round(pose.y_m * 1000.0 / self._conv),
                         theta_rad=pose.heading_rad, left_mm_s=left, right_mm_s=right,
                         battery_v=self.config.battery_v, left_stall=pushing, right_stall=pushing,
                         front_bumpers=0, rear_bumpers=0, control_rad=control, motors_enabled=m.enabled)


def _signed_byte(b: int) -> int:
    return b - 256 if b > 127 else b


def _ramp(current: float, wanted: float, accel: float, decel: float, dt: float) -> float:
    """Move ``current`` towards ``wanted``: ``accel`` when speeding up, ``decel`` when slowing down."""
    speeding_up = abs(wanted) > abs(current) and wanted * current >= 0.0
    limit = (accel if speeding_up else decel) * dt
    return current + max(-limit, min(limit, wanted - current))


def _approach(left: float, top: float, decel: float) -> float:
    """Speed towards a goal ``left`` away: capped, slowing so as to stop there (with a margin for
    the step's lag), exponential at the end."""
    braking = math.sqrt(2.0 * _BRAKING_MARGIN * decel * abs(left))
    return math.copysign(min(top, braking, _SETTLE_GAIN_PER_S * abs(left)), left)


def _set_accel(m: _Motion, value: int, turn: bool) -> None:
    """SETA/SETRA: a positive value sets the acceleration, a negative one the deceleration."""
    if value == 0:
        return
    name = ("turn_" if turn else "") + ("accel" if value > 0 else "decel") + ("_deg_s2" if turn else "_mm_s2")
    setattr(m, name, float(abs(value)))


_LIMIT_SETTERS = {
    Command.SETV: lambda m, v: setattr(m, "speed_max_mm_s", float(max(0, min(MAX_SPEED_MM_S, v)))),
    Command.SETRV: lambda m, v: setattr(m, "turn_max_deg_s", float(max(0, min(MAX_TURN_RATE_DEG_S, v)))),
    Command.SETA: lambda m, v: _set_accel(m, v, turn=False),
    Command.SETRA: lambda m, v: _set_accel(m, v, turn=True),
}
_MOTION_COMMANDS = (Command.VEL, Command.MOVE, Command.RVEL, Command.ROTATE, Command.HEAD, Command.DHEAD,
                    Command.VEL2)


class PioneerEmulator:
    """Serves a :class:`PioneerServerState` in real time, from one thread, on a pseudo-terminal (the
    default) or on a TCP port as the vendor's simulators do (``TcpPort``, a ``socket://`` URL)."""

    def __init__(self, state: PioneerServerState, terminal: PseudoTerminal | TcpPort | None = None):
        self.state = state
        self._terminal = terminal or PseudoTerminal()
        self._reader = arcos.PacketReader()
        self._stop = threading.Event()
        self.cable = Cable()
        self._lock = threading.Lock()  # the state is read by tests while the thread runs it
        self._thread = threading.Thread(target=self._serve, name="pioneer-emulator", daemon=True)

    @property
    def path(self) -> str:
        """The device path (or pyserial URL) a client opens."""
        return self._terminal.path

    def start(self) -> PioneerEmulator:
        self._thread.start()
        log.info("Pioneer emulator (%s) on %s", self.state.config.subtype, self.path)
        return self

    def snapshot(self) -> tuple[bool, bool, float, float]:
        """(session open, watchdog tripped, speed mm/s, turn rate deg/s), for tests."""
        with self._lock:
            m = self.state.motion
            return self.state.open, self.state.watchdog_tripped, m.speed_mm_s, m.turn_deg_s

    def history(self) -> list[tuple[int, int | str | None]]:
        """The recent commands received, oldest first."""
        with self._lock:
            return list(self.state.history)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._terminal.close()

    def __enter__(self) -> PioneerEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _serve(self) -> None:
        while not self._stop.is_set():
            data = self._terminal.read() if self._terminal.wait_readable(PHYSICS_STEP_S) else b""
            replies: list[bytes] = []
            with self._lock:
                now = time.monotonic()
                if data and self.cable.hears:
                    for packet in self._reader.feed(data):
                        replies += self.state.receive(packet, now)
                replies += self.state.step(now)
            if self.cable.talks:
                for reply in replies:
                    self._terminal.write(reply)
