"""Bad bytes into the ARCOS stream reader (hypothesis): random and garbled streams, any chunking.

The property: feeding any stream raises nothing, parsing any packet it yields (argument or SIP)
raises nothing but :class:`ArcosError`, and once a false header's count has passed the reader is
back in step: good packets come out exactly. ``onboard.fuzz`` runs it as a fuzz target
(``syt-offboard fuzz --only stream``; the test suite runs a short fuzz of it).
"""

from __future__ import annotations

from hypothesis import strategies as st

from onboard.hardware import arcos
from onboard.hardware.arcos import ArcosError, Command, PacketReader, build_packet

GOOD = build_packet(Command.VEL, -200)
_REAL_PACKETS = [GOOD, build_packet(Command.SYNC2), build_packet(Command.CONFIG, "abc"),
                 arcos.encode_sip(arcos.Sip(True, 0x7FF0, 12, 1.0, -100, 300, 12.7, True, False, 5, 64, -0.5,
                                            True, ((3, 1500), (7, 250))))]
# After garbage, enough good packets to outlast the longest packet a false header may announce.
_RESYNC = GOOD * (arcos.MAX_COUNT // len(GOOD) + 2)


@st.composite
def garbled_streams(draw: st.DrawFn) -> bytes:
    """Plain random bytes, or real packets with bits flipped, bytes dropped, headers and junk inserted."""
    if draw(st.booleans()):
        return draw(st.binary(max_size=600))
    stream = bytearray(b"".join(draw(st.lists(st.sampled_from(_REAL_PACKETS), max_size=6))))
    for _ in range(draw(st.integers(0, 8))):
        i = draw(st.integers(0, len(stream)))
        action = draw(st.sampled_from(["flip", "drop", "header", "insert"]))
        if action == "flip" and i < len(stream):
            stream[i] ^= 1 << draw(st.integers(0, 7))
        elif action == "drop" and i < len(stream):
            del stream[i]
        elif action == "header":
            stream[i:i] = arcos.HEADER + bytes([draw(st.integers(0, 255))])
        else:
            stream[i:i] = draw(st.binary(min_size=1, max_size=100))
    return bytes(stream)


def check_stream(stream: bytes, cuts: list[int]) -> None:
    """Feed ``stream`` then good packets, cut at ``cuts``; parse all that comes out; check the resync."""
    reader, packets = PacketReader(), []
    whole = stream + _RESYNC
    bounds = [0, *sorted(c % (len(whole) + 1) for c in cuts), len(whole)]
    for lo, hi in zip(bounds, bounds[1:]):
        packets += reader.feed(whole[lo:hi])
    for packet in packets:
        try:
            arcos.parse_arg(packet.payload)
            if packet.id in arcos.SIP_TYPES:
                arcos.parse_sip(packet)
            elif packet.id == Command.SYNC2:
                arcos.parse_sync2(packet.payload)
        except ArcosError:
            pass
    good = arcos.parse_packet(GOOD)
    if not packets or packets[-1] != good or reader.feed(GOOD) != [good]:
        raise AssertionError(f"no resync after {stream.hex(' ')}")
