"""Bad bytes into the PTU-D46 reply parser (hypothesis): random and garbled streams, any chunking.

The property: feeding any stream raises nothing, parsing any reply it yields raises nothing but
:class:`PtuError`, and good lines after a line end come out exactly. ``onboard.fuzz`` runs it as a fuzz target
(``syt-offboard fuzz --only stream``; the test suite runs a short fuzz of it).
"""

from __future__ import annotations

from hypothesis import strategies as st

from onboard.hardware.ptu_protocol import (LimitHit, PtuError, Reply, ReplyTokenizer, parse_decimal,
                                           parse_integer)

GOOD_LINES = [b"*", b"* 1167", b"* -3090", b"* 185.1428", b"!P", b"!T", b"! Illegal command XY",
              b"PP1000 *", b"Initializing...", b"* Pan-Tilt Controller v3.2.0"]
RESYNC = b"\r\n* 42\r\n!T\r\n! PP4000: outside PX 3090\r\n"
RESYNC_EVENTS = [Reply(True, "42"), LimitHit("tilt"), Reply(False, "PP4000: outside PX 3090")]


@st.composite
def garbled_streams(draw: st.DrawFn) -> bytes:
    """Good lines with bytes flipped, dropped and inserted, or plain random bytes."""
    if draw(st.booleans()):
        return draw(st.binary(max_size=600))
    lines = draw(st.lists(st.sampled_from(GOOD_LINES), max_size=12))
    stream = bytearray(b"\r\n".join(lines))
    for _ in range(draw(st.integers(0, 8))):
        if not stream:
            break
        i = draw(st.integers(0, len(stream) - 1))
        action = draw(st.sampled_from(["flip", "drop", "insert"]))
        if action == "flip":
            stream[i] ^= 1 << draw(st.integers(0, 7))
        elif action == "drop":
            del stream[i]
        else:
            stream[i:i] = draw(st.binary(min_size=1, max_size=300))
    return bytes(stream)


def check_stream(stream: bytes, cuts: list[int]) -> None:
    """Feed ``stream`` cut at ``cuts``, parse every reply, then check the resync."""
    tokenizer = ReplyTokenizer()
    bounds = [0, *sorted(c % (len(stream) + 1) for c in cuts), len(stream)]
    for lo, hi in zip(bounds, bounds[1:]):
        for event in tokenizer.feed(stream[lo:hi]):
            if isinstance(event, Reply):
                for parse in (parse_integer, parse_decimal):
                    try:
                        parse(event, "PP")
                    except PtuError:
                        pass
    tail = tokenizer.feed(RESYNC)
    if tail[-3:] != RESYNC_EVENTS:
        raise AssertionError(f"no resync after {stream!r}: {tail}")
