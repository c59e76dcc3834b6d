"""The emulated robot's truth, for a simulated camera in another process, over a Unix socket.

``syt-onboard emulate`` moves a simulated world with byte-level emulators; the agent talks to them
through the real serial drivers, so it knows only what they report (drifting odometry, the head's
positions). Its camera (``[hardware.camera] device = "sim"``) must render what the emulated robot
would see: the same world, from the robot's *true* pose and the head's true angles. The emulate
process serves both on a Unix socket whose path it announces as ``"truth"`` in its JSON line; the
agent's ``[hardware] truth`` names it.

A Unix socket, not Zenoh: the link is private to one machine and one robot, needs no key of the
agent's namespace (whose ``sim/truth`` belongs to the simulator backend) and no session of its own.

The exchange is one JSON line each way per connection: ``{"ask": "world"}`` answers the world file
and placement the emulators move (``WorldPlacement``); ``{"ask": "truth"}`` answers ``Truth``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import socket
import socketserver
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from onboard.devices import DeviceFault, PanTiltReading
from shared.geometry import Pose2D
from shared.strict import finite_float
from shared.world import World, resolve_world

log = logging.getLogger(__name__)

_MAX_LINE = 4096
_TIMEOUT_S = 2.0


class TruthLinkError(DeviceFault):
    """The truth link failed or answered nonsense; the message says which."""


@dataclass(frozen=True)
class WorldPlacement:
    """The world file the emulators move, where the robot started and where the target stands."""

    world: str  # absolute path of the world file
    start: tuple[float, float, float]  # x, y, heading (rad)
    target: tuple[float, float, float, float]  # bottom centre x, y, z (m), yaw (deg)

    @classmethod
    def of(cls, world: World, path_or_name: str | Path) -> WorldPlacement:
        t = world.target
        return cls(str(resolve_world(path_or_name).resolve()),
                   (world.start.x_m, world.start.y_m, world.start.heading_rad), (*t.position_m, t.yaw_deg))

    def load(self, robot_radius_m: float) -> World:
        """The world as the emulators move it (checked for rendering)."""
        from onboard.sim.world import load_world

        return (load_world(self.world, robot_radius_m=robot_radius_m)
                .with_target(*self.target).with_start(*self.start))


@dataclass(frozen=True)
class Truth:
    pose: Pose2D  # the true pose in the world
    pan_rad: float
    tilt_rad: float
    head_moving: bool


# --- the wire: pure ----------------------------------------------------------------------------------

def encode(message: dict) -> bytes:
    return json.dumps(message, separators=(",", ":")).encode() + b"\n"


def decode(line: bytes) -> dict:
    """One JSON object line; ``TruthLinkError`` naming what is wrong otherwise."""
    try:
        message = json.loads(line)
    except (ValueError, UnicodeDecodeError) as exc:
        raise TruthLinkError(f"truth link: not a JSON line ({exc})") from None
    if not isinstance(message, dict):
        raise TruthLinkError(f"truth link: expected a JSON object, got {type(message).__name__}")
    return message


def truth_to_dict(truth: Truth) -> dict:
    p = truth.pose
    return {"x_m": p.x_m, "y_m": p.y_m, "heading_rad": p.heading_rad, "pan_rad": truth.pan_rad,
            "tilt_rad": truth.tilt_rad, "head_moving": truth.head_moving}


def truth_from_dict(d: dict) -> Truth:
    """The truth in a reply; each value of its JSON type (no "1.5" or true for a number, no "no" for
    a flag, which ``float`` and ``bool`` would take)."""
    missing = [k for k in (*_TRUTH_NUMBERS, "head_moving") if k not in d]
    if missing:
        raise TruthLinkError(f"truth link: a truth reply lacks {', '.join(missing)}")
    for key in _TRUTH_NUMBERS:
        value = d[key]
        if not _is_number(value):
            raise TruthLinkError(f"truth link: a truth reply's {key} must be a finite number, got {value!r}")
    if not isinstance(d["head_moving"], bool):
        raise TruthLinkError(f"truth link: a truth reply's head_moving must be true or false, got {d['head_moving']!r}")
    x, y, heading, pan, tilt = (float(d[k]) for k in _TRUTH_NUMBERS)
    return Truth(Pose2D(x, y, heading), pan, tilt, d["head_moving"])


_TRUTH_NUMBERS = ("x_m", "y_m", "heading_rad", "pan_rad", "tilt_rad")


def _is_number(value: object) -> bool:
    """A finite JSON number: not true or false, not a string, not an integer beyond any float."""
    try:
        finite_float(value)
    except ValueError:
        return False
    return True


def placement_from_dict(d: dict) -> WorldPlacement:
    """The placement in a world reply, as strict as :func:`truth_from_dict`: a start of two numbers
    passed here once and failed later, in ``World.with_start``, as a bare TypeError."""
    missing = [k for k in ("world", "start", "target") if k not in d]
    if missing:
        raise TruthLinkError(f"truth link: a world reply lacks {', '.join(missing)}")
    if not isinstance(d["world"], str):
        raise TruthLinkError(f"truth link: a world reply's world must be a path, got {d['world']!r}")
    return WorldPlacement(d["world"], _numbers(d, "start", 3), _numbers(d, "target", 4))


def _numbers(d: dict, key: str, count: int) -> tuple[float, ...]:
    value = d[key]
    if (not isinstance(value, list) or len(value) != count
            or not all(_is_number(v) for v in value)):
        raise TruthLinkError(f"truth link: a world reply's {key} must be {count} finite numbers, got {value!r}")
    return tuple(float(v) for v in value)


# --- the server (in the emulate process) -------------------------------------------------------------

class TruthServer:
    """Answers on ``path`` from ``read_truth()`` and the fixed ``placement``, one thread per client."""

    def __init__(self, path: str | Path, placement: WorldPlacement, read_truth: Callable[[], Truth]):
        self.path = str(path)
        answers = {"world": lambda: dataclasses.asdict(placement),
                   "truth": lambda: truth_to_dict(read_truth())}

        class Handler(socketserver.StreamRequestHandler):
            def handle(self) -> None:
                try:
                    ask = decode(self.rfile.readline(_MAX_LINE)).get("ask")
                except TruthLinkError as exc:
                    self.wfile.write(encode({"error": str(exc)}))
                    return
                answer = answers.get(ask)
                self.wfile.write(encode(answer() if answer else {"error": f"unknown ask {ask!r}"}))

        self._server = socketserver.ThreadingUnixStreamServer(self.path, Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, args=(0.1,), name="truth-server",
                                        daemon=True)

    def start(self) -> TruthServer:
        self._thread.start()
        log.info("truth link on %s", self.path)
        return self

    def close(self) -> None:
        if self._thread.is_alive():
            self._server.shutdown()
        self._server.server_close()
        Path(self.path).unlink(missing_ok=True)


# --- the client (in the agent) -----------------------------------------------------------------------

class TruthLink:
    """Asks the emulate process over its Unix socket, one connection per question. It offers what a
    simulated camera reads from a simulated robot: ``true_pose`` and the head's ``reading()``."""

    def __init__(self, path: str):
        self.path = path

    def placement(self) -> WorldPlacement:
        return placement_from_dict(self._ask("world"))

    def truth(self) -> Truth:
        return truth_from_dict(self._ask("truth"))

    @property
    def true_pose(self) -> Pose2D:
        return self.truth().pose

    def reading(self) -> PanTiltReading:
        t = self.truth()
        return PanTiltReading(t.pan_rad, t.tilt_rad, t.head_moving)

    def _ask(self, what: str) -> dict:
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                sock.settimeout(_TIMEOUT_S)
                sock.connect(self.path)
                sock.sendall(encode({"ask": what}))
                line = sock.makefile("rb").readline(_MAX_LINE)
        except OSError as exc:
            raise TruthLinkError(f"truth link {self.path}: {exc} (is syt-onboard emulate running?)") from None
        reply = decode(line)
        if "error" in reply:
            raise TruthLinkError(f"truth link {self.path}: {reply['error']}")
        return reply
