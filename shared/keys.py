"""Every Zenoh key expression of the system, under ``syt/<robot_id>/``.

| key                          | kind        | payload (shared.messages)            |
|------------------------------|-------------|--------------------------------------|
| ``syt/<id>/move``            | queryable   | MoveCommand → MoveResult             |
| ``syt/<id>/stop``            | queryable   | StopCommand → StopResult             |
| ``syt/<id>/look``            | queryable   | LookCommand → LookResult             |
| ``syt/<id>/capture``         | queryable   | CaptureCommand → Capture             |
| ``syt/<id>/state``           | queryable   | StateRequest → StateReply            |
| ``syt/<id>/info``            | queryable   | InfoRequest → Info                   |
| ``syt/<id>/sim/truth``       | queryable   | StateRequest → SimTruth (simulator)  |
| ``syt/<id>/sim/teleport``    | queryable   | SimTeleport → SimTruth (simulator)   |
| ``syt/<id>/sim/reset``       | queryable   | SimReset → SimTruth (simulator)      |
| ``syt/<id>/sim/fault``       | queryable   | SimFault → SimTruth (simulator)      |
| ``syt/<id>/odometry``        | publication | Odometry, steady rate, latest-only   |
| ``syt/<id>/pantilt``         | publication | PanTiltState, steady rate            |
| ``syt/<id>/heartbeat``       | publication | Heartbeat, from the planner          |
| ``syt/<id>/agent``           | liveliness  | held while the onboard agent runs    |
| ``syt/<id>/planner/<pid>``   | liveliness  | held while a planner drives the robot|

Errors come back as ``reply_err`` carrying an ErrorReply.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_ROBOT_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")


def check_robot_id(robot_id: str) -> str:
    """Robot (and planner) ids become one key chunk: no slashes or wildcards."""
    if not _ROBOT_ID.fullmatch(robot_id):  # match with "$" lets a trailing newline through
        raise ValueError(f"id {robot_id!r} must be 1-64 letters, digits, '_' or '-'")
    return robot_id


@dataclass(frozen=True)
class RobotKeys:
    robot_id: str

    def __post_init__(self) -> None:
        check_robot_id(self.robot_id)

    def _key(self, leaf: str) -> str:
        return f"syt/{self.robot_id}/{leaf}"

    @property
    def move(self) -> str:
        return self._key("move")

    @property
    def stop(self) -> str:
        return self._key("stop")

    @property
    def look(self) -> str:
        return self._key("look")

    @property
    def capture(self) -> str:
        return self._key("capture")

    @property
    def state(self) -> str:
        return self._key("state")

    @property
    def info(self) -> str:
        return self._key("info")

    @property
    def sim_truth(self) -> str:
        return self._key("sim/truth")

    @property
    def sim_teleport(self) -> str:
        return self._key("sim/teleport")

    @property
    def sim_reset(self) -> str:
        return self._key("sim/reset")

    @property
    def sim_fault(self) -> str:
        return self._key("sim/fault")

    @property
    def odometry(self) -> str:
        return self._key("odometry")

    @property
    def pantilt(self) -> str:
        return self._key("pantilt")

    @property
    def heartbeat(self) -> str:
        return self._key("heartbeat")

    @property
    def agent_alive(self) -> str:
        return self._key("agent")

    def planner_alive(self, planner_id: str) -> str:
        return self._key(f"planner/{check_robot_id(planner_id)}")

    @property
    def any_planner_alive(self) -> str:
        return self._key("planner/*")
