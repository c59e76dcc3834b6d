"""The fuzz targets of the decoders in ``shared``: the message codec (one target per message type)
and the world format; and :func:`toml_target`, with which each program fuzzes its own TOML files
(configs through :func:`shared.config.load_config`, the search's hints).

Every target starts from valid inputs and breaks them one way per case (:mod:`shared.mutation`).
A message case is a msgpack payload broken in a field of the body, in the envelope (schema, type,
body) or in its bytes; a TOML case is a file broken in a key or in its text. TOML decoders are
given a real file, as on the command line.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
from hypothesis import strategies as st

from shared import messages as m
from shared import toml_writer
from shared.codec import ProtocolError, decode, encode
from shared.fuzzing import Case, FuzzTarget
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits
from shared.mutation import plain_cases, toml_damage, wire_damage
from shared.world import WORLDS_DIR, WorldError, load_world

_POSE = m.PoseMsg(1.5, 2.0, 90.0)
_INTRINSICS = m.IntrinsicsMsg(4, 3, 3.0, 3.0, 1.5, 1.0)
_MOUNT = m.MountMsg(1.2, 0.0, 0.12)
_STATE = m.RobotState(_POSE, 0.3, -10.0, 30.0, -5.0, True, False, False, 12.5)
_IMAGE = np.arange(36, dtype=np.uint8).reshape(3, 4, 3)

# Valid messages of every type: what the cases start from.
SAMPLES: tuple[Any, ...] = (
    m.MoveCommand("c1", 90.0, 1.5, None, 0.4), m.MoveCommand("c2", waypoint_m=(3.0, 2.0)),
    m.StopCommand("c3"), m.LookCommand("c4", 30.0, -10.0), m.CaptureCommand("c5", "png"),
    m.StateRequest("c6"), m.InfoRequest("c7"), m.ErrorReply("c8", "limit", "pan_deg=200 is outside"),
    m.MoveResult("c9", "stalled", _POSE, 1.2, 3.0, 40.0), m.StopResult("c10", _POSE, 41.0),
    m.LookResult("c11", 30.0, -10.0, 0.8, 42.0),
    m.Capture("c12", _IMAGE, _IMAGE[::-1].copy(), _POSE, 30.0, -10.0, _INTRINSICS, _MOUNT, 43.0, 0.1),
    _STATE, m.StateReply("c13", _STATE), m.Odometry(7, _POSE, 0.3, -10.0, True, False, 44.0),
    m.PanTiltState(7, 30.0, -10.0, False, 44.0),
    m.Info("c14", "pioneer1", "sim", BaseLimits(), PanTiltLimits(), CameraTiming(), _INTRINSICS, _MOUNT, 1000),
    m.Heartbeat("planner-1", 3), m.SimTruth("c15", _POSE, 45.0), m.SimTeleport("c16", _POSE),
    m.SimReset("c17", _POSE, (4.0, 2.5, 0.75), -90.0, 11), m.SimFault("c18", "camera", 0.5),
)


def _bodies(name: str) -> list[dict[str, Any]]:
    """The valid bodies of a message type as they travel (both array encodings for a capture)."""
    samples = [s for s in SAMPLES if type(s).__name__ == name]
    return [msgpack.unpackb(encode(s, arrays), raw=False)["body"] for s in samples
            for arrays in (("raw", "png") if name == "Capture" else ("raw",))]


def _envelope(name: str, body: Any) -> bytes:
    return msgpack.packb({"schema": m.SCHEMA_VERSION, "type": name, "body": body}, use_bin_type=True)


def message_cases(name: str) -> st.SearchStrategy[Case]:
    """Payloads of message type ``name`` broken in the body, the envelope or the bytes."""
    cls, bodies = m.MESSAGE_TYPES[name], _bodies(name)
    payloads = [_envelope(name, body) for body in bodies]
    in_body = plain_cases(bodies, cls, wire=True).map(lambda c: Case(_envelope(name, c[0]), **c[1]))
    in_bytes = st.sampled_from(payloads).flatmap(wire_damage).map(lambda d: Case(d[0], None, d[2], d[1]))
    return st.one_of(in_body, in_body, in_body, _envelope_cases(name, bodies), in_bytes)


def _envelope_cases(name: str, bodies: list[dict[str, Any]]) -> st.SearchStrategy[Case]:
    other_types = sorted(set(m.MESSAGE_TYPES) - {name})
    wrong = st.sampled_from([
        ("schema", st.sampled_from([0, 2, -1, "1", None, True, 1.0, [1]])),
        ("type", st.sampled_from(["NoSuchMessage", name.lower(), 7, None, name.encode(), [name], *other_types])),
        ("body", st.sampled_from([None, 1, "body", [], [bodies[0]]])),
        ("", st.sampled_from(["missing", "extra", "list", "scalar"])),
    ]).flatmap(lambda kv: kv[1].map(lambda v: (kv[0], v)))

    @st.composite
    def cases(draw: st.DrawFn) -> Case:
        key, value = draw(wrong)
        envelope = {"schema": m.SCHEMA_VERSION, "type": name, "body": draw(st.sampled_from(bodies))}
        if key:
            envelope[key] = value
            return Case(msgpack.packb(envelope, use_bin_type=True), key if key != "body" else None, True,
                        f"envelope {key} = {value!r}")
        if value == "missing":
            del envelope[draw(st.sampled_from(sorted(envelope)))]
        elif value == "extra":
            envelope["version"] = 2
        whole = {"missing": envelope, "extra": envelope, "list": [envelope], "scalar": 42}[value]
        return Case(msgpack.packb(whole, use_bin_type=True), None, True, f"envelope {value}")
    return cases()


def message_targets() -> list[FuzzTarget]:
    """One target per message type: ``decode(payload, ThatType)`` must raise only ProtocolError."""
    def target(name: str) -> FuzzTarget:
        cls = m.MESSAGE_TYPES[name]
        return FuzzTarget(f"message {name}", lambda: message_cases(name), lambda p: decode(p, cls), ProtocolError)
    return [target(name) for name in m.MESSAGE_TYPES if name not in unsampled_types()]


def unsampled_types() -> list[str]:
    """Message types with no valid sample in :data:`SAMPLES`: not fuzzed until one is added."""
    return sorted(set(m.MESSAGE_TYPES) - {type(s).__name__ for s in SAMPLES})


# --- TOML files -------------------------------------------------------------------------------------

def on_file(load: Callable[[Path], Any]) -> Callable[[bytes], Any]:
    """A decoder of file contents that hands ``load`` a real file holding them."""
    def decode_file(data: bytes) -> Any:
        with tempfile.NamedTemporaryFile(suffix=".toml") as file:
            file.write(data)
            file.flush()
            return load(Path(file.name))
    return decode_file


def toml_cases(valid: list[dict[str, Any]], texts: list[str], cls: type | None) -> st.SearchStrategy[Case]:
    """TOML files broken in one key (typed by ``cls`` when given) or in their text."""
    in_key = plain_cases(valid, cls, wire=False).map(lambda c: Case(toml_writer.dumps(c[0]).encode(), **c[1]))
    all_texts = texts + [toml_writer.dumps(v) for v in valid]
    in_text = st.sampled_from(all_texts).flatmap(toml_damage).map(lambda d: Case(d[0], None, d[2], d[1]))
    return st.one_of(in_key, in_key, in_key, in_text)


def toml_target(name: str, load: Callable[[Path], Any], error: type[BaseException], texts: list[str],
                cls: type | None = None) -> FuzzTarget:
    """A target for a TOML file format read by ``load(path)``; ``texts`` are valid files of it."""
    import tomllib

    valid = [tomllib.loads(t) for t in texts]
    return FuzzTarget(name, lambda: toml_cases(valid, texts, cls), on_file(load), error)


def world_target() -> FuzzTarget:
    """The world format, from the bundled worlds; ``load_world`` must raise only WorldError."""
    texts = [p.read_text() for p in sorted(WORLDS_DIR.glob("*.toml"))]
    return toml_target("world toml", load_world, WorldError, texts)


def shared_targets() -> list[FuzzTarget]:
    return [*message_targets(), world_target()]
