"""The onboard agent: serves the robot's devices to a planner over Zenoh.

Threads, and why each exists:
- Zenoh's callbacks only put queries on a bounded FIFO (nothing blocks inside a callback);
- the *dispatcher* decodes and checks each command, answers the quick ones (state, info, stop)
  and hands motions and captures to
- one *worker per device* (base, pan-tilt, camera), so a stop is served while the base moves and a
  second motion for a busy device is refused rather than queued;
- the *publisher* sends odometry and pan/tilt state at a steady rate (latest-only: DROP);
- the *watchdog* stops the base when the planner that sent the move under way goes silent or its
  liveliness token vanishes. A planner names itself in each command (the query's attachment), in its
  heartbeats and in its token's key, so another planner's heartbeats never keep its motion alive.

Safety: the base is stopped at start-up (a Pioneer resumes its last motion when communication
returns), by the watchdog, and in ``finally`` when the agent ends for any reason.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import msgpack
import zenoh

from onboard import signals
from onboard.config import OnboardConfig
from onboard.devices import DeviceFault, Devices, SimControl
from shared import messages as m
from shared.codec import ProtocolError, decode, encode
from shared.keys import RobotKeys
from shared.strict import StructureError

log = logging.getLogger(__name__)

REQUEST_TYPES: dict[str, type] = {
    "move": m.MoveCommand, "stop": m.StopCommand, "look": m.LookCommand,
    "capture": m.CaptureCommand, "state": m.StateRequest, "info": m.InfoRequest,
    "sim_truth": m.StateRequest, "sim_teleport": m.SimTeleport, "sim_reset": m.SimReset,
    "sim_fault": m.SimFault,
}
_SIM_ONLY = ("sim_truth", "sim_teleport", "sim_reset", "sim_fault")
# Only a planner's commands count as word from it: anyone may poll state or info (an observer, a
# dashboard, a crowd of them), and that must not keep alive a motion whose planner froze.
_PLANNER_COMMANDS = ("move", "stop", "look", "capture")
_WATCHDOG_POLL_S = 0.02  # how often the watchdog looks at a moving base
_ARRIVED_M = 1e-3  # a waypoint this near the robot is where it stands


def _sender(query: zenoh.Query) -> str:
    """The planner id a command names itself by (its attachment); "" if none."""
    attachment = query.attachment
    return attachment.to_bytes().decode("utf-8", "replace")[:64] if attachment is not None else ""


class CommandRefused(Exception):
    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


def _busy(device: str) -> CommandRefused:
    return CommandRefused("busy", f"the {device} is executing another command; send stop first")


class DeviceWorker:
    """One thread per device; ``try_submit`` refuses a job while the previous one runs."""

    close_timeout_s = 5.0  # how long close waits for a job under way before leaving it behind

    def __init__(self, name: str):
        self.name = name
        self._jobs: queue.Queue[Callable[[], Callable[[], None] | None] | None] = queue.Queue(maxsize=1)
        self._busy = threading.Event()
        self._thread = threading.Thread(target=self._loop, name=f"worker-{name}", daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        return self._busy.is_set()

    def try_submit(self, job: Callable[[], Callable[[], None] | None]) -> bool:
        """Run ``job`` on the device's thread; it may return the reply to send once the device is free."""
        if self._busy.is_set():
            return False
        self._busy.set()
        self._jobs.put(job)
        return True

    def close(self) -> None:
        try:  # a device stuck in a job holds a queued one: give up on it rather than hang the agent's exit
            self._jobs.put(None, timeout=self.close_timeout_s)
        except queue.Full:
            pass
        self._thread.join(timeout=self.close_timeout_s)
        if self._thread.is_alive():
            log.error("%s worker: still busy after %g s; left behind", self.name, self.close_timeout_s)

    def _loop(self) -> None:
        while (job := self._jobs.get()) is not None:
            answer = None
            try:
                answer = job()
            except Exception:  # a device fault must not kill the worker
                log.exception("%s worker: job failed", self.name)
            finally:
                self._busy.clear()  # free before the reply: the planner's next command may follow at once
            try:
                if answer is not None:
                    answer()
            except Exception:  # nor a failed reply: the thread would be gone and the device busy for good
                log.exception("%s worker: reply failed", self.name)


@dataclass
class _PlannerWatch:
    """Which planner owns the move under way, when each planner last spoke, and whose token is gone."""

    owner: str = ""  # the planner that sent the move under way ("" for one that did not name itself)
    last_contact_s: dict[str, float] = field(default_factory=dict)  # planner id -> monotonic time
    gone: set[str] = field(default_factory=set)  # planners whose liveliness token was withdrawn, not renewed
    bad_heartbeat: bool = False  # the last sample on the heartbeat key was not one: said once, not at every beat

    def heard(self, planner: str, at_s: float | None = None) -> None:
        """Word from ``planner`` at ``at_s`` (monotonic; default now): never earlier than word already heard."""
        at_s = time.monotonic() if at_s is None else at_s
        self.last_contact_s[planner] = max(at_s, self.last_contact_s.get(planner, at_s))


class Agent:
    def __init__(self, config: OnboardConfig, devices: Devices, session: zenoh.Session, robot_id: str,
                 sim: SimControl | None = None):
        self.config = config
        self.devices = devices
        self.session = session
        self.keys = RobotKeys(robot_id)
        self._sim = sim
        # each command with the number of stops heard before it: a motion that a later stop overtook is not started
        # (_fresh_cancel), since a stop that found the queue full is not in it to stop the motion in its turn;
        # and when it arrived: that, not when the dispatcher takes it up, is when its planner was last heard
        self._commands: queue.Queue[tuple[str, zenoh.Query, int, float] | None] = queue.Queue(maxsize=64)
        self._workers = {name: DeviceWorker(name) for name in ("base", "pantilt", "camera")}
        self._cancel = {"base": threading.Event(), "pantilt": threading.Event()}
        self._watch = _PlannerWatch()
        self._shutdown = threading.Event()
        self._wake_watchdog = threading.Event()  # a lost planner is acted on at once, not at the next poll
        # a stop is acted on by the watchdog's thread as it arrives, before it is decoded or queued (the
        # queue may be full, the dispatcher blocked), and again by the dispatcher in its place in the
        # queue, readable or not; the lock keeps the early stop from landing on a move the dispatcher
        # starts after that
        self._stop_asked = threading.Event()
        self._stop_lock = threading.Lock()
        self._stops_heard = 0  # every word on the stop key, counted as it arrives (_enqueuer)
        self._queue_lock = threading.Lock()  # a count and a place in the queue go together; never held long
        self._dispatching_after = 0  # the stops heard before the command the dispatcher is serving
        self._declared: list = []
        self._threads: list[threading.Thread] = []

    # --- lifecycle -----------------------------------------------------------------------------------

    def run(self, stop: threading.Event) -> None:
        """Serve until ``stop`` is set; the base is stopped whatever happens."""
        try:
            self.devices.base.stop()
            self._declare()
            for target in (self._dispatch_loop, self._publish_loop, self._watchdog_loop):
                thread = threading.Thread(target=target, name=target.__name__.strip("_"), daemon=True)
                thread.start()
                self._threads.append(thread)
            log.info("agent ready: robot %r, backend %s, keys under syt/%s/", self.keys.robot_id,
                     self.devices.backend, self.keys.robot_id)
            signals.wait(stop)
        finally:
            self._close()

    def _declare(self) -> None:
        for kind in REQUEST_TYPES:
            if kind in _SIM_ONLY and self._sim is None:
                continue
            key = getattr(self.keys, kind)
            self._declared.append(self.session.declare_queryable(key, self._enqueuer(kind)))
        self._declared.append(self.session.declare_subscriber(self.keys.heartbeat, self._on_heartbeat))
        self._declared.append(self.session.liveliness().declare_subscriber(
            self.keys.any_planner_alive, self._on_planner_liveliness, history=True))
        self._odometry_pub = self.session.declare_publisher(
            self.keys.odometry, congestion_control=zenoh.CongestionControl.DROP)
        self._pantilt_pub = self.session.declare_publisher(
            self.keys.pantilt, congestion_control=zenoh.CongestionControl.DROP)
        self._declared += [self._odometry_pub, self._pantilt_pub]
        self._token = self.session.liveliness().declare_token(self.keys.agent_alive)

    def _close(self) -> None:
        self._shutdown.set()
        self._wake_watchdog.set()
        for cancel in self._cancel.values():
            cancel.set()
        try:
            self.devices.close()
        finally:
            self._commands.put(None)
            for worker in self._workers.values():
                worker.close()
            for thread in self._threads:  # the publisher mid-tick must not put on an undeclared publisher
                thread.join(timeout=2.0)
            for entity in self._declared + [getattr(self, "_token", None)]:
                if entity is not None:
                    entity.undeclare()
            log.info("agent stopped; base stopped")

    # --- callbacks: never block ----------------------------------------------------------------------

    def _enqueuer(self, kind: str) -> Callable[[zenoh.Query], None]:
        def enqueue(query: zenoh.Query) -> None:
            try:
                with self._queue_lock:  # put_nowait never blocks
                    self._stops_heard += kind == "stop"
                    self._commands.put_nowait((kind, query, self._stops_heard, time.monotonic()))
            except queue.Full:
                self._reply_error(query, "", "busy", "command queue full; the agent is overloaded")
            finally:
                if kind == "stop":  # whatever its payload, queued or not: any word on the stop key stops the robot
                    self._stop_asked.set()
                    self._wake_watchdog.set()
        return enqueue

    def _on_heartbeat(self, sample: zenoh.Sample) -> None:
        try:  # only a heartbeat is word from the planner, not anything put on its key
            beat = decode(sample.payload.to_bytes(), m.Heartbeat)
        except ProtocolError as exc:
            if not self._watch.bad_heartbeat:
                log.warning("ignoring what is not a heartbeat on %s: %s", sample.key_expr, exc)
            self._watch.bad_heartbeat = True
            return
        self._watch.bad_heartbeat = False
        self._watch.heard(beat.planner_id)

    def _on_planner_liveliness(self, sample: zenoh.Sample) -> None:
        planner = str(sample.key_expr).rsplit("/", 1)[-1]
        if sample.kind == zenoh.SampleKind.DELETE:
            log.warning("planner gone: %s", sample.key_expr)
            self._watch.gone.add(planner)
            self._wake_watchdog.set()
        else:
            log.info("planner connected: %s", sample.key_expr)
            self._watch.gone.discard(planner)
            self._watch.heard(planner)

    # --- dispatcher ----------------------------------------------------------------------------------

    def _dispatch_loop(self) -> None:
        while (item := self._commands.get()) is not None:
            kind, query, self._dispatching_after, arrived_s = item
            payload = query.payload.to_bytes() if query.payload is not None else b""
            try:
                command = decode(payload, REQUEST_TYPES[kind])
                if self._shutdown.is_set():
                    raise CommandRefused("shutdown", "the agent is shutting down")
                if kind in _PLANNER_COMMANDS:  # a well-formed command, not any bytes on its key
                    # a move that waited behind a stop's 2 s must not stretch a silent planner's watchdog
                    self._watch.heard(_sender(query), arrived_s)
                getattr(self, f"_on_{kind}")(query, command)
            except ProtocolError as exc:
                log.warning("%s: malformed command: %s", kind, exc)
                if kind == "stop":  # unreadable, but a stop all the same: the moves queued before it too
                    self._stop_in_order("malformed stop command")
                self._reply_error(query, _guess_command_id(payload), "protocol", str(exc))
            except CommandRefused as exc:
                log.warning("%s refused: %s", kind, exc)
                self._reply_error(query, _guess_command_id(payload), exc.code, str(exc))
            except Exception as exc:  # a device fault: make the robot safe, answer, keep serving
                log.exception("%s failed", kind)
                self._stop_all(f"{kind} failed")
                self._reply_error(query, _guess_command_id(payload), "device", f"{type(exc).__name__}: {exc}")

    def _submit(self, device: str, query: zenoh.Query, command_id: str, job: Callable[[], object],
                arrays: str = "raw") -> None:
        def run() -> Callable[[], None]:
            try:
                result = job()
            except Exception as exc:  # a device fault: the motors may still run, so stop, then answer
                log.exception("%s job failed", device)
                self._stop_all(f"{device} fault")
                text = f"{type(exc).__name__}: {exc}"
                return lambda: self._reply_error(query, command_id, "device", text)
            return lambda: self._reply(query, result, arrays)
        if not self._workers[device].try_submit(run):
            raise _busy(device)

    def _on_move(self, query: zenoh.Query, cmd: m.MoveCommand) -> None:
        turn_rad, distance_m = self._resolve_motion(cmd)
        limits = self.devices.base.limits
        speed = cmd.speed_m_s if cmd.speed_m_s is not None else limits.default_speed_m_s
        if speed > limits.max_speed_m_s:
            raise CommandRefused("limit", f"speed_m_s={speed:g} exceeds the base's max_speed_m_s={limits.max_speed_m_s:g}")
        owner = _sender(query)
        if owner in self._watch.gone:  # queued before its token went: nobody is left to stop it
            raise CommandRefused("planner", f"planner {owner!r} is gone (its liveliness token was withdrawn)")
        cancel = self._fresh_cancel("base")
        self._watch.owner = owner

        def job() -> m.MoveResult:
            start = self.devices.clock.now_s()
            outcome = self.devices.base.move(turn_rad, distance_m, speed, cancel)
            log.info("move %s: %s after %.2f m", cmd.command_id, outcome.status, outcome.distance_m)
            return m.MoveResult(cmd.command_id, outcome.status, self._pose(), outcome.distance_m,
                                outcome.duration_s, max(start, self.devices.clock.now_s()))
        self._submit("base", query, cmd.command_id, job)

    def _fresh_cancel(self, device: str) -> threading.Event:
        """A new cancel flag for the device's next job (only when it is free: a busy one is refused)."""
        if self._workers[device].busy:
            raise _busy(device)
        cancel = self._cancel[device] = threading.Event()
        # Set at once, and the job ends where the device stands, when _close cancelled the flags before
        # this one was in place, or when a stop came after the command was queued: one that found the
        # queue full is not in it to stop the motion in its turn. (A stop after this check sets this flag.)
        if self._shutdown.is_set() or self._stops_heard > self._dispatching_after:
            cancel.set()
        return cancel

    def _resolve_motion(self, cmd: m.MoveCommand) -> tuple[float, float]:
        limits = self.devices.base.limits
        if cmd.waypoint_m is not None:
            pose = self.devices.base.reading().pose
            distance_m = pose.distance_to(*cmd.waypoint_m)
            if distance_m > limits.max_distance_m:
                raise CommandRefused("limit", f"waypoint_m={list(cmd.waypoint_m)} is {distance_m:g} m away, more "
                                              f"than max_distance_m={limits.max_distance_m:g}")
            if distance_m < _ARRIVED_M:  # already there: its bearing is noise, a turn to it spins for nothing
                return 0.0, 0.0
            turn_rad = pose.bearing_to(*cmd.waypoint_m)
            if abs(math.degrees(turn_rad)) > limits.max_turn_deg:
                raise CommandRefused("limit", f"waypoint_m={list(cmd.waypoint_m)} takes a turn of "
                                              f"{math.degrees(turn_rad):g}°, more than max_turn_deg={limits.max_turn_deg:g}")
            return turn_rad, distance_m
        turn_rad, distance_m = math.radians(cmd.turn_deg), cmd.distance_m
        if abs(math.degrees(turn_rad)) > limits.max_turn_deg:
            raise CommandRefused("limit", f"turn_deg={math.degrees(turn_rad):g} exceeds max_turn_deg={limits.max_turn_deg:g}")
        if abs(distance_m) > limits.max_distance_m:
            raise CommandRefused("limit", f"distance_m={distance_m:g} exceeds max_distance_m={limits.max_distance_m:g}")
        return turn_rad, distance_m

    def _on_stop(self, query: zenoh.Query, cmd: m.StopCommand) -> None:
        if failed := self._stop_in_order("stop command"):
            raise CommandRefused("device", "; ".join(failed))
        deadline = time.monotonic() + 2.0
        while self.devices.base.reading().moving and time.monotonic() < deadline:
            time.sleep(0.002)
        self._reply(query, m.StopResult(cmd.command_id, self._pose(), self.devices.clock.now_s()))

    def _on_look(self, query: zenoh.Query, cmd: m.LookCommand) -> None:
        problem = self.devices.pantilt.limits.check(cmd.pan_deg, cmd.tilt_deg)
        if problem:
            raise CommandRefused("limit", problem)
        cancel = self._fresh_cancel("pantilt")

        def job() -> m.LookResult:
            duration = self.devices.pantilt.look(math.radians(cmd.pan_deg), math.radians(cmd.tilt_deg), cancel)
            head = self.devices.pantilt.reading()
            return m.LookResult(cmd.command_id, math.degrees(head.pan_rad), math.degrees(head.tilt_rad),
                                duration, self.devices.clock.now_s())
        self._submit("pantilt", query, cmd.command_id, job)

    def _on_capture(self, query: zenoh.Query, cmd: m.CaptureCommand) -> None:
        def job() -> m.Capture:
            camera, head = self.devices.camera, self.devices.pantilt.reading()
            exposure_s, pose = self.devices.clock.now_s(), self._pose()
            images = camera.capture()
            return m.Capture(cmd.command_id, images.left, images.right, pose,
                             math.degrees(head.pan_rad), math.degrees(head.tilt_rad),
                             m.IntrinsicsMsg.from_intrinsics(camera.intrinsics),
                             m.MountMsg.from_mount(camera.mount), exposure_s,
                             self.devices.clock.now_s() - exposure_s)
        self._submit("camera", query, cmd.command_id, job, arrays=cmd.encoding)

    def _on_state(self, query: zenoh.Query, cmd: m.StateRequest) -> None:
        self._reply(query, m.StateReply(cmd.command_id, self.state()))

    def _on_info(self, query: zenoh.Query, cmd: m.InfoRequest) -> None:
        d = self.devices
        self._reply(query, m.Info(cmd.command_id, self.keys.robot_id, d.backend, d.base.limits,
                                  d.pantilt.limits, self.config.timing,
                                  m.IntrinsicsMsg.from_intrinsics(d.camera.intrinsics),
                                  m.MountMsg.from_mount(d.camera.mount), self.config.watchdog_ms,
                                  d.clock.realtime))

    def _on_sim_truth(self, query: zenoh.Query, cmd: m.StateRequest) -> None:
        self._reply(query, m.SimTruth(cmd.command_id, m.PoseMsg.from_pose(self._sim.true_pose),
                                      self.devices.clock.now_s()))

    def _on_sim_teleport(self, query: zenoh.Query, cmd: m.SimTeleport) -> None:
        if self._workers["base"].busy:
            raise CommandRefused("busy", "cannot teleport while the base moves")
        problem = self._sim.teleport(cmd.pose.to_pose())
        if problem:
            raise CommandRefused("limit", problem)
        self._on_sim_truth(query, m.StateRequest(cmd.command_id))

    def _on_sim_reset(self, query: zenoh.Query, cmd: m.SimReset) -> None:
        busy = [name for name, worker in self._workers.items() if worker.busy]
        if busy:
            raise CommandRefused("busy", f"cannot reset while {', '.join(busy)} works")
        problem = self._sim.reset(cmd.start.to_pose(), cmd.target_m, cmd.target_yaw_deg, cmd.seed)
        if problem:
            raise CommandRefused("limit", problem)
        self._on_sim_truth(query, m.StateRequest(cmd.command_id))

    def _on_sim_fault(self, query: zenoh.Query, cmd: m.SimFault) -> None:
        self._sim.inject_fault(cmd.device, cmd.after_s)
        log.warning("simulator: the %s's next operation will fail %.3f s into it", cmd.device, cmd.after_s)
        self._on_sim_truth(query, m.StateRequest(cmd.command_id))

    # --- state, publishing, watchdog -----------------------------------------------------------------

    def _pose(self) -> m.PoseMsg:
        return m.PoseMsg.from_pose(self.devices.base.reading().pose)

    def state(self) -> m.RobotState:
        base, head = self.devices.base.reading(), self.devices.pantilt.reading()
        return m.RobotState(m.PoseMsg.from_pose(base.pose), base.speed_m_s, math.degrees(base.turn_rate_rad_s),
                            math.degrees(head.pan_rad), math.degrees(head.tilt_rad), base.moving,
                            head.moving, base.stalled, self.devices.clock.now_s())

    def _publish_loop(self) -> None:
        period, seq, why_not = 1.0 / self.config.publish_hz, 0, ""  # why_not: why the last tick published nothing
        due = time.monotonic() + period
        while not self._shutdown.wait(max(0.0, due - time.monotonic())):
            # A fixed schedule: a late wake-up shortens the next wait instead of slowing the rate
            # (on a busy machine, waiting a whole period after each late tick gave 8 Hz, not 10).
            due = max(due + period, time.monotonic())
            try:
                s = self.state()
                odometry = encode(m.Odometry(seq, s.pose, s.speed_m_s, s.turn_rate_deg_s, s.base_moving, s.stalled,
                                             s.robot_time_s))
                pantilt = encode(m.PanTiltState(seq, s.pan_deg, s.tilt_deg, s.pantilt_moving, s.robot_time_s))
            except (DeviceFault, StructureError) as exc:  # a serial link down, or a reading the planner would refuse
                cause = "a device fault" if isinstance(exc, DeviceFault) else "a reading out of range"
                if cause != why_not:
                    log.warning("not publishing (%s): %s", cause, exc)
                why_not = cause
                continue
            if why_not:
                log.info("publishing again after %s", why_not)
                why_not = ""
            self._odometry_pub.put(odometry)
            self._pantilt_pub.put(pantilt)
            seq += 1

    def _watchdog_loop(self) -> None:
        timeout_s = self.config.watchdog_ms / 1000.0
        wait_s = _WATCHDOG_POLL_S
        while not self._shutdown.is_set():
            self._wake_watchdog.wait(wait_s)
            self._wake_watchdog.clear()
            wait_s = _WATCHDOG_POLL_S
            with self._stop_lock:
                if self._stop_asked.is_set():
                    self._stop_asked.clear()
                    self._stop_all("stop asked")
                    continue
            try:
                if not self.devices.base.reading().moving:
                    continue
            except DeviceFault:  # link down: no stop could reach the base; its firmware halts it (2 s)
                continue
            owner = self._watch.owner
            silent_s = time.monotonic() - self._watch.last_contact_s.get(owner, 0.0)
            if owner in self._watch.gone:
                self._stop_all(f"planner {owner!r} lost (liveliness token gone)")
            elif silent_s >= timeout_s:
                self._stop_all(f"watchdog: no word from the planner for {silent_s * 1000:.0f} ms")
            else:
                wait_s = min(wait_s, timeout_s - silent_s)  # wake on the deadline itself

    def _stop_in_order(self, why: str) -> list[str]:
        """The dispatcher's stop, in the stop's place in the queue: the watchdog's early one for it is
        then no longer due (:meth:`_stop_all`)."""
        with self._stop_lock:
            self._stop_asked.clear()
            return self._stop_all(why)

    def _stop_all(self, why: str) -> list[str]:
        """Cancel every job, stop the base and halt the head, each even if another fails: this runs on
        the watchdog's and the dispatcher's threads, which must outlive a dead device. Returns what
        did not stop, one line a device."""
        log.warning("stopping the base: %s", why)
        for cancel in self._cancel.values():
            cancel.set()
        failed = []
        for name, stop in (("base", self.devices.base.stop), ("pan-tilt", self.devices.pantilt.halt)):
            try:
                stop()
            except Exception as exc:  # whatever a backend raises, the next device must still be stopped
                failed.append(f"the {name} did not stop: {type(exc).__name__}: {exc}")
                log.error("%s", failed[-1])
        return failed

    # --- replies -------------------------------------------------------------------------------------

    def _reply(self, query: zenoh.Query, message: object, arrays: str = "raw") -> None:
        try:
            payload = encode(message, arrays)
        except StructureError as exc:  # a device read out of any range: say so, not leave the planner waiting
            log.error("reply not sent: %s", exc)
            self._reply_error(query, getattr(message, "command_id", ""), "device", f"the reply is out of range: {exc}")
            return
        query.reply(query.key_expr, payload)
        query.drop()

    def _reply_error(self, query: zenoh.Query, command_id: str, code: str, text: str) -> None:
        query.reply_err(encode(m.ErrorReply(command_id, code, text)))
        query.drop()


def _guess_command_id(payload: bytes) -> str:
    """Echo the command id of a malformed command when one can be read."""
    try:
        command_id = msgpack.unpackb(payload, raw=False)["body"]["command_id"]
    except Exception:
        return ""
    return command_id if isinstance(command_id, str) and len(command_id) <= 64 else ""
