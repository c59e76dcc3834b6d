"""The planner's handle on a remote robot: every onboard command as a method, over Zenoh.

While open it holds the planner's liveliness token and publishes heartbeats, so the robot's
watchdog stops the base if this process dies, freezes or loses the link.
"""

from __future__ import annotations

import itertools
import logging
import math
import os
import re
import socket
import threading
import time
import uuid

import zenoh

from shared import messages as m
from shared.codec import encode
from shared.keys import RobotKeys
from shared.rpc import CommandError, RobotUnavailable, request

log = logging.getLogger(__name__)

__all__ = ["RobotClient", "CommandError", "RobotUnavailable"]

_LONGEST_MOTION_S = 3600.0


class RobotClient:
    def __init__(self, session: zenoh.Session, robot_id: str):
        self.session = session
        self.keys = RobotKeys(robot_id)
        self.planner_id = re.sub(r"[^A-Za-z0-9_-]", "-", f"{socket.gethostname()}-{os.getpid()}")[:64]
        self._ids = itertools.count()
        self._info: m.Info | None = None
        self._closed = threading.Event()
        self._token = session.liveliness().declare_token(self.keys.planner_alive(self.planner_id))
        self._heartbeat_pub = session.declare_publisher(self.keys.heartbeat,
                                                        congestion_control=zenoh.CongestionControl.DROP)
        self._heartbeat = threading.Thread(target=self._beat, name="heartbeat", daemon=True)
        self._heartbeat.start()

    def __enter__(self) -> RobotClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Withdraw the planner's token (the robot stops any motion under way); idempotent."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._heartbeat.join(timeout=2.0)
        self._heartbeat_pub.undeclare()
        self._token.undeclare()

    # --- connection ----------------------------------------------------------------------------------

    def wait_for_robot(self, timeout_s: float = 15.0) -> m.Info:
        """Wait until the agent's liveliness token is seen, then fetch its description."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if any(r.ok is not None for r in self.session.liveliness().get(self.keys.agent_alive, timeout=0.5)):
                return self.info()
            time.sleep(0.05)
        raise RobotUnavailable(f"robot {self.keys.robot_id!r} did not appear within {timeout_s:g} s")

    def info(self) -> m.Info:
        self._info = self._request(self.keys.info, m.InfoRequest(self._next_id()), m.Info, 5.0)
        return self._info

    # --- commands ------------------------------------------------------------------------------------

    def move(self, turn_deg: float = 0.0, distance_m: float = 0.0, speed_m_s: float | None = None) -> m.MoveResult:
        """Turn in place by ``turn_deg`` (counter-clockwise), then drive ``distance_m``."""
        cmd = m.MoveCommand(self._next_id(), turn_deg=turn_deg, distance_m=distance_m, speed_m_s=speed_m_s)
        return self._request(self.keys.move, cmd, m.MoveResult, self._motion_timeout_s(turn_deg, distance_m, speed_m_s))

    def move_to(self, x_m: float, y_m: float, speed_m_s: float | None = None) -> m.MoveResult:
        """Turn towards the world point (as the robot's odometry sees it) and drive to it."""
        cmd = m.MoveCommand(self._next_id(), waypoint_m=(x_m, y_m), speed_m_s=speed_m_s)
        farthest_m = (self._info or self.info()).base.max_distance_m  # the robot refuses a waypoint farther
        return self._request(self.keys.move, cmd, m.MoveResult, self._motion_timeout_s(180.0, farthest_m, speed_m_s))

    def stop(self) -> m.StopResult:
        return self._request(self.keys.stop, m.StopCommand(self._next_id()), m.StopResult, 5.0)

    def look(self, pan_deg: float, tilt_deg: float) -> m.LookResult:
        return self._request(self.keys.look, m.LookCommand(self._next_id(), pan_deg, tilt_deg), m.LookResult,
                             self._look_timeout_s())

    def capture(self, encoding: str = "raw") -> m.Capture:
        return self._request(self.keys.capture, m.CaptureCommand(self._next_id(), encoding), m.Capture, 30.0)

    def state(self) -> m.RobotState:
        return self._request(self.keys.state, m.StateRequest(self._next_id()), m.StateReply, 5.0).state

    def sim_truth(self) -> m.PoseMsg:
        """Simulator only (tests and benchmarks): the true pose, which a planner must never use."""
        return self._request(self.keys.sim_truth, m.StateRequest(self._next_id()), m.SimTruth, 5.0).pose

    def sim_teleport(self, x_m: float, y_m: float, heading_deg: float) -> m.PoseMsg:
        """Simulator only (calibration and tests): put the robot at a pose, truth and odometry."""
        cmd = m.SimTeleport(self._next_id(), m.PoseMsg(x_m, y_m, heading_deg))
        return self._request(self.keys.sim_teleport, cmd, m.SimTruth, 5.0).pose

    def sim_reset(self, start: tuple[float, float, float], target: tuple[float, float, float, float],
                  seed: int) -> m.PoseMsg:
        """Simulator only (experiment sweeps): a new run — start (x, y, heading°), target (x, y, z of its
        bottom face, yaw°), odometry-noise seed."""
        cmd = m.SimReset(self._next_id(), m.PoseMsg(*start), tuple(target[:3]), target[3], seed)
        return self._request(self.keys.sim_reset, cmd, m.SimTruth, 30.0).pose

    # --- internals -----------------------------------------------------------------------------------

    def _next_id(self) -> str:
        return f"{uuid.uuid4().hex[:8]}-{next(self._ids)}"

    def _request(self, key: str, command: object, expected: type, timeout_s: float):
        return request(self.session, key, command, expected, timeout_s, sender=self.planner_id)

    def _motion_timeout_s(self, turn_deg: float, distance_m: float, speed_m_s: float | None) -> float:
        """Generous: the robot's own time for the motion at the speed asked (when paced in real time) and a
        margin; at most an hour, so that an absurd distance reaches the robot and is refused there by name
        (one outside the message's range, or not finite, is refused here, by the encoder)."""
        info = self._info or self.info()
        expected = (info.base.turn_time_s(math.radians(turn_deg))
                    + info.base.drive_time_s(distance_m, speed_m_s))
        return min(_LONGEST_MOTION_S, 2.0 * expected + 10.0)

    def _look_timeout_s(self) -> float:
        """The head's slowest slew, corner to corner at the unit's own speeds, twice, and the capture's margin."""
        head = (self._info or self.info()).pantilt
        slowest = head.slew_time_s(head.pan_max_deg - head.pan_min_deg, head.tilt_max_deg - head.tilt_min_deg)
        return 2.0 * slowest + 30.0

    def _beat(self) -> None:
        for seq in itertools.count():
            if self._closed.wait(m.HEARTBEAT_PERIOD_S):
                return
            try:
                self._heartbeat_pub.put(encode(m.Heartbeat(self.planner_id, seq)))
            except zenoh.ZError:  # the session is closing
                return

