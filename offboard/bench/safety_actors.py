"""The processes the safety bench starts, kills and freezes: each a real process with its own Zenoh
session, run as ``python -m offboard.bench.safety_actors ROLE ...``.

- ``planner ENDPOINT``: a real :class:`RobotClient` (planner liveliness token, 5 Hz heartbeats)
  that commands one long drive;
- ``router LISTEN AGENT``: a Zenoh router between a planner and the agent, so the link can drop;
- ``load ENDPOINT SECONDS``: a client that queries ``state`` as fast as it can.

Each imports everything, prints ``loaded`` and waits for a line on stdin before it opens its session:
the bench starts the next one while a trial runs, and an idle actor holds no token and sends nothing.
It then prints ``ready`` (connected) and, for a planner, ``moving`` once the move is sent.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import threading
import time

import zenoh

from offboard.robot.robot_client import CommandError, RobotClient, RobotUnavailable
from shared import messages as m
from shared.keys import RobotKeys
from shared.rpc import request
from shared.transport import DEFAULT_LEASE_MS, TransportConfig

log = logging.getLogger(__name__)

DRIVE_M = 8.0  # longer than any trial lasts
DRIVE_SPEED_M_S = 0.5


def _say(word: str) -> None:
    sys.stdout.write(word + "\n")
    sys.stdout.flush()


def run_planner(endpoint: str, mode: str, lease_ms: int) -> None:
    """Hold a planner's token, heartbeat, and drive until killed, frozen or cut off."""
    transport = TransportConfig(connect=(endpoint,), mode=mode, multicast_scouting=False, lease_ms=lease_ms)
    with transport.open() as session, RobotClient(session, transport.robot_id) as robot:
        robot.wait_for_robot(30.0)
        _say("ready")
        mover = threading.Thread(target=_drive, args=(robot,), daemon=True)
        mover.start()
        _say("moving")
        mover.join()


def _drive(robot: RobotClient) -> None:
    try:
        log.info("drive ended: %s", robot.move(distance_m=DRIVE_M, speed_m_s=DRIVE_SPEED_M_S).status)
    except (CommandError, RobotUnavailable) as exc:  # the bench judges by the robot, not by this reply
        log.info("drive ended: %s", exc)


def run_router(listen: str, agent: str, lease_ms: int) -> None:
    """A Zenoh router listening for the planner and connected to the agent; lives until killed."""
    config = TransportConfig(connect=(agent,), listen=(listen,), multicast_scouting=False, lease_ms=lease_ms).zenoh()
    config.insert_json5("mode", json.dumps("router"))
    with zenoh.open(config):
        _say("ready")
        threading.Event().wait()


def run_load(endpoint: str, seconds: float) -> None:
    """Query ``state`` back to back for ``seconds``; print the replies and the errors as JSON."""
    transport = TransportConfig(connect=(endpoint,), multicast_scouting=False)
    keys = RobotKeys(transport.robot_id)
    replies = errors = 0
    with transport.open() as session:
        _say("ready")
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                request(session, keys.state, m.StateRequest(f"load-{replies + errors}"), m.StateReply, 5.0)
                replies += 1
            except RuntimeError:  # busy or unanswered (CommandError, RobotUnavailable): counted
                errors += 1
    _say(json.dumps({"replies": replies, "errors": errors, "seconds": seconds}))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m offboard.bench.safety_actors")
    parser.add_argument("--lease-ms", type=int, default=DEFAULT_LEASE_MS)
    roles = parser.add_subparsers(dest="role", required=True)
    planner = roles.add_parser("planner")
    planner.add_argument("endpoint")
    planner.add_argument("--mode", choices=("peer", "client"), default="peer")
    router = roles.add_parser("router")
    router.add_argument("listen")
    router.add_argument("agent")
    load = roles.add_parser("load")
    load.add_argument("endpoint")
    load.add_argument("seconds", type=float)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    _say("loaded")
    sys.stdin.readline()  # the go
    if args.role == "planner":
        run_planner(args.endpoint, args.mode, args.lease_ms)
    elif args.role == "router":
        run_router(args.listen, args.agent, args.lease_ms)
    else:
        run_load(args.endpoint, args.seconds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
