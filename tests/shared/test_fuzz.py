"""The fuzz runner, the shared decoders' targets (a short run of each), and what fuzzing found."""

import math

import msgpack
import pytest

from shared import messages as m
from shared import toml_writer
from shared.codec import ProtocolError, decode, encode
from shared.config import ConfigError, load_config
from shared.fuzz_targets import SAMPLES, on_file, shared_targets, unsampled_types
from shared.fuzzing import Case, FuzzTarget, run_target
from shared.world import WORLDS_DIR, WorldError, load_world

CASES = 60  # each; `syt-offboard fuzz --cases 10000` is the full run


@pytest.mark.parametrize("target", shared_targets(), ids=lambda t: t.name)
def test_shared_decoders_pass_a_short_fuzz(target):
    report = run_target(target, CASES)
    assert report.cases >= CASES
    assert report.failures == 0, report.examples
    assert report.refused > CASES // 2  # the cases really are bad input, mostly


def test_every_message_type_has_a_sample():
    assert unsampled_types() == []


# --- the runner catches each kind of failure ---------------------------------------------------------

def _target(decode_fn, case: Case) -> FuzzTarget:
    from hypothesis import strategies as st

    return FuzzTarget("stub", lambda: st.just(case), decode_fn, ProtocolError)


def _raise(exc):
    def decode_fn(data):
        raise exc
    return decode_fn


BROKEN_X = Case(b"x", "pose.x_m", True, "x broken")


@pytest.mark.parametrize("decode_fn, fails", [
    (_raise(ProtocolError("pose.x_m", 1, "bad")), False),
    (_raise(KeyError("pose")), True),  # another exception type
    (_raise(ProtocolError("", 1, "something is wrong")), True),  # does not name pose.x_m
    (lambda data: None, True),  # accepts what must be refused
])
def test_the_runner_counts_every_kind_of_failure(decode_fn, fails):
    report = run_target(_target(decode_fn, BROKEN_X), 5)
    assert report.cases >= 5
    assert report.failures == (report.cases if fails else 0)
    assert bool(report.examples) == fails


def _nested(depth: int) -> int:
    return 0 if depth == 0 else 1 + _nested(depth - 1)


def test_a_decoder_that_recurses_past_pythons_limit_fails_though_hypothesis_raises_the_limit():
    report = run_target(_target(lambda data: _nested(1500), Case(b"z", None, False, "deep")), 5)
    assert report.failures == report.cases and "RecursionError" in report.examples[0]


def test_a_case_that_may_be_valid_may_be_accepted():
    report = run_target(_target(lambda data: None, Case(b"y", "pose.x_m", False, "other value")), 5)
    assert (report.failures, report.accepted) == (0, report.cases)


# --- what fuzzing found (fixed) ----------------------------------------------------------------------

def _with_schema(schema) -> bytes:
    return msgpack.packb({"schema": schema, "type": "StopCommand", "body": {"command_id": "a"}})


@pytest.mark.parametrize("schema", [True, 1.0])
def test_a_schema_that_only_equals_1_is_refused(schema):
    with pytest.raises(ProtocolError, match="^schema:"):
        decode(_with_schema(schema), m.StopCommand)


def _capture_with_left(header: dict) -> bytes:
    capture = next(s for s in SAMPLES if isinstance(s, m.Capture))
    envelope = msgpack.unpackb(encode(capture), raw=False)
    envelope["body"]["left"] = header
    return msgpack.packb(envelope)


@pytest.mark.parametrize("header", [
    {"dtype": "uint8", "shape": [3, 4, 3], "encoding": "png", "data": b""},  # OpenCV raised cv2.error
    {"dtype": "uint8", "shape": [65536] * 4, "encoding": "raw", "data": b""},  # np.prod wrapped to 0
])
def test_array_headers_that_crashed_the_codec_are_refused(header):
    with pytest.raises(ProtocolError, match="^left.data:"):
        decode(_capture_with_left(header), m.Capture)


HOSTILE_TOML = {
    "integer beyond a float": None,  # set per format below: the key must be named
    "5000-digit integer": b"huge = 1" + b"0" * 5000 + b"\n",  # tomllib raised ValueError
    "deep nesting": b"deep = " + b"[" * 600 + b"]" * 600 + b"\n",  # tomllib raised RecursionError
    "invalid UTF-8": b"name = \"\xff\"\n",  # read_text raised UnicodeDecodeError
}
HOSTILE_SAYS = {"5000-digit integer": "4300 digits", "deep nesting": "recursion", "invalid UTF-8": "can't decode byte 0xff"}


@pytest.mark.parametrize("how", [h for h in HOSTILE_TOML if HOSTILE_TOML[h]])
def test_hostile_toml_is_a_config_error(how):
    from shared.limits import BaseLimits

    with pytest.raises(ConfigError, match=HOSTILE_SAYS[how]):
        on_file(lambda p: load_config(BaseLimits, p))(HOSTILE_TOML[how])


@pytest.mark.parametrize("how", [h for h in HOSTILE_TOML if HOSTILE_TOML[h]])
def test_hostile_toml_is_a_world_error(how):
    text = (WORLDS_DIR / "paper-lab.toml").read_bytes()
    with pytest.raises(WorldError, match=HOSTILE_SAYS[how]):
        on_file(load_world)(HOSTILE_TOML[how] + text)


def test_an_integer_beyond_a_float_names_its_key():
    from shared.limits import BaseLimits

    with pytest.raises(ConfigError, match="max_speed_m_s"):
        on_file(lambda p: load_config(BaseLimits, p))(b"max_speed_m_s = 1" + b"0" * 400 + b"\n")
    import tomllib

    world = tomllib.loads((WORLDS_DIR / "paper-lab.toml").read_text())
    world["robot"]["heading_deg"] = 10**400
    with pytest.raises(WorldError, match="^robot.heading_deg:"):
        on_file(load_world)(toml_writer.dumps(world).encode())


def test_the_toml_writer_round_trips_what_the_fuzzer_writes():
    import datetime as dt
    import tomllib

    data = {"name": "a \"b\" \\ \x01 é", "x": 1.5, "n": 10**30, "d": dt.date(2024, 2, 29), "bad key": [1, [2]],
            "room": {"size": [1, 2.5, 3], "sub": {"a": True}}, "obstacle": [{"min": [0, 0]}, {"k": {"i": 1}}]}
    assert tomllib.loads(toml_writer.dumps(data)) == data
    assert math.isnan(tomllib.loads(toml_writer.dumps({"v": math.nan}))["v"])


def test_a_literal_option_must_have_its_type_too():
    from dataclasses import dataclass
    from typing import Literal

    from shared.strict import StructureError, build

    @dataclass(frozen=True)
    class Costed:
        cost_function: Literal[1, 2, 3, 4] = 3

    for value in (3.0, True):
        with pytest.raises(StructureError, match="^cost_function:"):
            build(Costed, {"cost_function": value})
    assert build(Costed, {"cost_function": 2}).cost_function == 2
