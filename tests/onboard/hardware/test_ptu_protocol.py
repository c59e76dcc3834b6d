"""The PTU-D46 protocol: command bytes, reply tokenizing in any chunks, units, bad bytes."""

from __future__ import annotations

import math

import pytest

from onboard.hardware.ptu_fuzz import RESYNC, RESYNC_EVENTS
from onboard.hardware.ptu_protocol import (LimitHit, Noise, PtuError, Reply, ReplyTokenizer, command,
                                           parse_decimal, parse_integer, positions_to_rad,
                                           rad_to_positions)


def test_command_bytes():
    assert command("PP", -300) == b"PP-300 "
    assert command("TP") == b"TP "
    assert command("PS", 1167) == b"PS1167 "
    assert command("HT") == b"HT "


@pytest.mark.parametrize("name, value, words", [
    ("XX", None, "not a PTU-D46 command"),
    ("PN", 3, "takes no argument"),
    ("PP", 100_000, "within"),
    ("PP", 1.5, "integer"),
])
def test_bad_commands_name_the_command(name, value, words):
    with pytest.raises(PtuError, match=f"^{name}: .*{words}"):
        command(name, value)


def test_tokenizer_splits_replies_fed_byte_by_byte():
    stream = (b"Pan-Tilt Controller v3\r\nInitializing...\r\nED *\r\n*\r\n* -3090\r\n"
              b"! PP4000: outside PX 3090\r\n!P\r\n\r\n* 185.1428\r\n")
    tokenizer = ReplyTokenizer()
    events = [e for byte in stream for e in tokenizer.feed(bytes([byte]))]
    assert events == [Noise("Pan-Tilt Controller v3"), Noise("Initializing..."), Reply(True, ""),
                      Reply(True, ""), Reply(True, "-3090"), Reply(False, "PP4000: outside PX 3090"),
                      LimitHit("pan"), Reply(True, "185.1428")]
    assert ReplyTokenizer().feed(stream) == events


def test_tokenizer_drops_an_over_long_line_and_resyncs():
    tokenizer = ReplyTokenizer(max_line_bytes=16)
    events = tokenizer.feed(b"*" * 40)
    assert len(events) == 1 and isinstance(events[0], Noise)
    assert tokenizer.feed(b"* 7 more of the long line\r\n* 8\r\n") == [Reply(True, "8")]


def test_garbled_bytes_are_noise_not_replies():
    assert ReplyTokenizer().feed(b"*\x00\xff 3\r\n!\x07\r\n") == [Noise("*\x00\xff 3"), Noise("!\x07")]


def test_parsing_answers():
    assert parse_integer(Reply(True, "-907"), "TN") == -907
    assert parse_integer(Reply(True, "Current pan position is 12"), "PP") == 12
    assert parse_decimal(Reply(True, "185.1428"), "PR") == pytest.approx(185.1428)
    with pytest.raises(PtuError, match=r"^PP: refused by the unit: Illegal"):
        parse_integer(Reply(False, "Illegal command"), "PP")
    with pytest.raises(PtuError, match=r"^PR: expected a number"):
        parse_decimal(Reply(True, "lots"), "PR")
    with pytest.raises(PtuError, match=r"^PP: expected an integer"):
        parse_integer(Reply(True, ""), "PP")


def test_position_conversions():
    res = 185.1428
    assert math.degrees(positions_to_rad(3090, res)) == pytest.approx(158.91, abs=0.01)
    assert rad_to_positions(math.radians(-46.6), res) == -906
    for pos in (-3090, -907, 0, 1, 604, 3090):
        assert rad_to_positions(positions_to_rad(pos, res), res) == pos


def test_resync_sequence_is_recognised_from_a_clean_start():
    assert ReplyTokenizer().feed(RESYNC) == RESYNC_EVENTS
