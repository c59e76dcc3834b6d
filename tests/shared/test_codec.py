"""The wire contract: every message round-trips, and every kind of bad payload is one ProtocolError."""

import math

import cv2
import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from shared import messages as m
from shared.codec import MAX_PAYLOAD_BYTES, ProtocolError, decode, encode
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits
from shared.strict import StructureError

POSE = m.PoseMsg(1.5, 2.0, 90.0)
INTR = m.IntrinsicsMsg(8, 6, 5.0, 5.0, 3.5, 2.5)
MOUNT = m.MountMsg(1.2, 0.0, 0.12)


def _image(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (6, 8, 3), dtype=np.uint8)


EXAMPLES = [
    m.MoveCommand("c1", turn_deg=90.0, distance_m=1.0),
    m.MoveCommand("c2", waypoint_m=(3.0, 4.0), speed_m_s=0.3),
    m.StopCommand("c3"), m.LookCommand("c4", -30.0, 15.0), m.CaptureCommand("c5", "png"),
    m.StateRequest("c6"), m.InfoRequest("c7"),
    m.ErrorReply("c8", "limit", "pan too far"),
    m.MoveResult("c9", "stalled", POSE, 0.4, 1.2, 10.0),
    m.StopResult("c10", POSE, 3.0), m.LookResult("c11", 10.0, 0.0, 0.5, 4.0),
    m.Capture("c12", _image(0), _image(1), POSE, 0.0, 30.0, INTR, MOUNT, 5.0, 0.1),
    m.RobotState(POSE, 0.1, 0.0, 0.0, 0.0, True, False, False, 1.0),
    m.StateReply("c13", m.RobotState(POSE, 0.0, 0.0, 5.0, 5.0, False, False, True, 2.0)),
    m.Odometry(3, POSE, 0.2, 10.0, True, False, 1.0), m.PanTiltState(4, 1.0, 2.0, False, 1.0),
    m.Info("c14", "syt", "sim", BaseLimits(), PanTiltLimits(), CameraTiming(), INTR, MOUNT, 1000),
    m.Heartbeat("planner-1", 7), m.SimTruth("c15", POSE, 1.0), m.SimTeleport("c16", POSE),
    m.SimReset("c17", POSE, (1.7, 4.5, 0.75), -90.0, 3), m.SimFault("c18", "base", 0.5),
]


def _equal(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(_equal(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    return a == b


def test_every_message_type_has_an_example():
    assert {type(e).__name__ for e in EXAMPLES} == set(m.MESSAGE_TYPES)


@pytest.mark.parametrize("message", EXAMPLES, ids=lambda e: type(e).__name__)
@pytest.mark.parametrize("arrays", ["raw", "png"])
def test_round_trip(message, arrays):
    assert _equal(decode(encode(message, arrays), type(message)), message)


def test_arrays_travel_as_bytes_with_a_header_not_as_lists():
    capture = EXAMPLES[11]
    body = msgpack.unpackb(encode(capture, "png"))["body"]
    assert body["left"]["encoding"] == "png" and isinstance(body["left"]["data"], bytes)
    assert body["left"]["shape"] == [6, 8, 3] and body["left"]["dtype"] == "uint8"
    assert msgpack.unpackb(encode(capture))["body"]["right"]["encoding"] == "raw"


def _payload(type_name: str, body: dict, schema: int = m.SCHEMA_VERSION) -> bytes:
    return msgpack.packb({"schema": schema, "type": type_name, "body": body}, use_bin_type=True)


LOOK = {"command_id": "x", "pan_deg": 10.0, "tilt_deg": 0.0}
GARBAGE = [
    (b"\xc1\xff\x00garbage", "not a msgpack payload"),
    (msgpack.packb([1, 2]), "expected a map with exactly schema, type and body"),
]
BAD = [
    ("old schema", _payload("LookCommand", LOOK, schema=0), "schema"),
    ("unknown type", _payload("FlyCommand", LOOK), "type"),
    ("unknown field", _payload("LookCommand", {**LOOK, "zoom": 2.0}), "zoom"),
    ("missing field", _payload("LookCommand", {"command_id": "x", "pan_deg": 1.0}), "tilt_deg"),
    ("wrong type", _payload("LookCommand", {**LOOK, "pan_deg": "ten"}), "pan_deg"),
    ("bool for number", _payload("LookCommand", {**LOOK, "pan_deg": True}), "pan_deg"),
    ("NaN", _payload("LookCommand", {**LOOK, "tilt_deg": math.nan}), "tilt_deg"),
    ("infinity", _payload("LookCommand", {**LOOK, "tilt_deg": math.inf}), "tilt_deg"),
    ("out of range", _payload("LookCommand", {**LOOK, "tilt_deg": 500.0}), "tilt_deg"),
    ("bad literal", _payload("CaptureCommand", {"command_id": "x", "encoding": "jpeg"}), "encoding"),
    ("tuple length", _payload("MoveCommand", {"command_id": "x", "waypoint_m": [1.0]}), "waypoint_m"),
    ("nested", _payload("MoveResult", {"command_id": "x", "status": "done", "pose": {"x_m": 1.0, "y_m": 2.0},
                                       "distance_m": 0.0, "duration_s": 0.0, "robot_time_s": 0.0}), "pose.heading_deg"),
    ("reset target", _payload("SimReset", {"command_id": "x", "start": {"x_m": 1.0, "y_m": 2.0, "heading_deg": 0.0},
                                           "target_m": [1.0, 2.0], "target_yaw_deg": 0.0, "seed": 0}), "target_m"),
]


@pytest.mark.parametrize("payload,says", GARBAGE)
def test_garbage_raises_one_protocol_error_saying_what_it_is(payload, says):
    with pytest.raises(ProtocolError, match=says):
        decode(payload, m.LookCommand)


@pytest.mark.parametrize("name,payload,field", BAD, ids=[b[0] for b in BAD])
def test_bad_payloads_raise_one_protocol_error_naming_the_field(name, payload, field):
    with pytest.raises(ProtocolError) as err:
        decode(payload, m.LookCommand, m.CaptureCommand, m.MoveCommand, m.MoveResult, m.SimReset)
    assert err.value.field.startswith(field)
    assert field in str(err.value)


def test_a_command_id_must_not_be_empty():
    with pytest.raises(ProtocolError, match="command_id must have 1 to 64 characters"):
        decode(_payload("LookCommand", {**LOOK, "command_id": ""}), m.LookCommand)


def _capture_body(**left_changes) -> bytes:
    body = msgpack.unpackb(encode(EXAMPLES[11]))["body"]
    body["left"].update(left_changes)
    return _payload("Capture", body)


@pytest.mark.parametrize("change", [
    {"data": b"short"}, {"dtype": "complex128"}, {"dtype": []}, {"dtype": {"a": 1}}, {"shape": [6, -8, 3]}, {"encoding": "jpeg"},
    {"encoding": "png"},  # raw bytes labelled as PNG
    {"shape": [6, 8, 4], "data": bytes(6 * 8 * 4)},  # not RGB: refused by the message's own check
])
def test_bad_arrays_are_refused(change):
    with pytest.raises(ProtocolError) as err:
        decode(_capture_body(**change), m.Capture)
    assert err.value.field.startswith("left") or "left" in str(err.value)


def test_expected_type_is_enforced():
    with pytest.raises(ProtocolError, match="expected LookResult"):
        decode(encode(m.StopCommand("s")), m.LookResult)


@pytest.mark.parametrize("depth", [1000, 1020])  # msgpack unpacks to 1023 levels, deeper than repr can go
def test_arrays_nested_as_deep_as_msgpack_allows_are_a_protocol_error(depth):
    with pytest.raises(ProtocolError, match=r"expected a map .*got \[\[\[\[\.\.\.\]\]\]\]"):
        decode(b"\x91" * depth + b"\xc0")


def test_a_large_rejected_bytes_value_is_named_without_being_copied_whole():
    import tracemalloc

    big = b"\x01" * (20 * 1024 * 1024)  # 20 MB where the command id should be
    payload = msgpack.packb({"schema": 1, "type": "StopCommand", "body": {"command_id": big}}, use_bin_type=True)
    tracemalloc.start()
    try:
        with pytest.raises(ProtocolError, match=r"command_id: expected a string \(got 20971520 bytes: b'\\x01") as refused:
            decode(payload, m.StopCommand)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(str(refused.value)) < 300
    assert peak < 30 * 1024 * 1024  # the value, not its repr (80 MB) as well

@given(st.binary(max_size=200))
def test_random_bytes_never_escape_as_anything_but_protocol_error(data):
    try:
        decode(data)
    except ProtocolError:
        pass


@given(pan=st.floats(-360, 360), tilt=st.floats(-90, 90), cid=st.text(min_size=1, max_size=64))
def test_look_commands_round_trip(pan, tilt, cid):
    cmd = m.LookCommand(cid, pan, tilt)
    assert decode(encode(cmd), m.LookCommand) == cmd


def test_a_png_whose_header_disagrees_with_the_shape_is_refused_before_it_is_decoded(monkeypatch):
    big = cv2.imencode(".png", np.zeros((2000, 3000, 3), np.uint8))[1].tobytes()  # a few kB, 18 MB decoded
    decoded = []
    monkeypatch.setattr(cv2, "imdecode", lambda *a: decoded.append(a))  # a spy: a bomb must not reach it
    with pytest.raises(ProtocolError, match=r"PNG of \(3000, 2000\)") as err:
        decode(_capture_body(encoding="png", data=big), m.Capture)
    assert err.value.field == "left.data" and not decoded


@pytest.mark.parametrize("shape", [(4, 5), (4, 5, 1), (4, 5, 2), (4, 5, 3), (4, 5, 4), (0, 5, 3), (4, 5, 3, 1)])
def test_every_array_asked_to_travel_as_png_comes_back_as_it_was(shape):
    """One channel came back from PNG as 2-D and was refused; two channels or an empty image raised a
    bare cv2.error. Those travel raw now."""
    from shared.codec import _decode_array, _encode_array

    array = np.arange(math.prod(shape), dtype=np.uint8).reshape(shape)
    back = _decode_array(_encode_array(array, "png"), "x")
    assert back.shape == array.shape and np.array_equal(back, array)


def test_a_robot_that_says_capture_takes_no_time_is_refused():
    """A look of 0 s would be worth infinitely much a second: the planner took it again and again."""
    envelope = msgpack.unpackb(encode(m.Info("c14", "syt", "sim", BaseLimits(), PanTiltLimits(), CameraTiming(),
                                             INTR, MOUNT, 1000)))
    envelope["body"]["camera"]["capture_s"] = 0.0  # as a robot of another build might send it
    with pytest.raises(ProtocolError) as err:
        decode(msgpack.packb(envelope), m.Info)
    assert err.value.field == "camera.capture_s"


@pytest.mark.parametrize("message, field", [
    (m.LookCommand("x", 400.0, 0.0), "pan_deg"),
    (m.LookCommand("x", 0.0, math.nan), "tilt_deg"),
    (m.LookCommand("x", np.float32(400.0), 0.0), "pan_deg"),  # a numpy number travels as the number it is
    (m.LookCommand("x", True, 0.0), "pan_deg"),
    (m.Heartbeat("p", np.int64(-1)), "seq"),
    (m.SimFault("f", "gripper", 0.0), "device"),
    (m.Info("c14", "syt", "sim", BaseLimits(), PanTiltLimits(), CameraTiming(capture_s=0.0), INTR, MOUNT, 1000),
     "camera.capture_s"),
])
def test_a_message_out_of_range_is_refused_where_it_is_made(message, field):
    """The sender's bug is named on the sender's side, not left for the other process to report."""
    with pytest.raises(StructureError) as err:
        encode(message)
    assert err.value.field == field


def test_a_payload_over_the_limit_is_refused_before_it_is_unpacked(monkeypatch):
    import shared.codec

    payload = encode(m.LookCommand("x", 10.0, 0.0))
    assert decode(payload, m.LookCommand).pan_deg == 10.0
    monkeypatch.setattr(shared.codec, "MAX_PAYLOAD_BYTES", len(payload) - 1)
    with pytest.raises(ProtocolError, match=rf"payload larger than {len(payload) - 1} bytes \(got '{len(payload)} bytes'\)"):
        decode(payload, m.LookCommand)
    assert MAX_PAYLOAD_BYTES >= 2 * 1280 * 960 * 3  # a raw stereo pair of 1280 × 960 colour images passes
