"""The ARCOS codec against the reference vectors, round trips, and garbled streams (hypothesis)."""

from __future__ import annotations

import math

import pytest

from onboard.hardware import arcos, arcos_fuzz
from onboard.hardware.arcos import ArcosError, Command, PacketReader, build_packet

VECTORS = [  # from the Pioneer 3 Operations Manual: (command, argument, bytes)
    (Command.SYNC0, None, "FA FB 03 00 00 00"), (Command.SYNC1, None, "FA FB 03 01 00 01"),
    (Command.SYNC2, None, "FA FB 03 02 00 02"), (Command.ENABLE, 1, "FA FB 06 04 3B 01 00 05 3B"),
    (Command.E_STOP, None, "FA FB 03 37 00 37"), (Command.VEL, 200, "FA FB 06 0B 3B C8 00 D3 3B"),
    (Command.VEL, -200, "FA FB 06 0B 1B C8 00 D3 1B"), (Command.HEAD, 90, "FA FB 06 0C 3B 5A 00 66 3B"),
    (Command.DHEAD, -45, "FA FB 06 0D 1B 2D 00 3A 1B"), (Command.MOVE, 1000, "FA FB 06 08 3B E8 03 F0 3E"),
    (Command.RVEL, 30, "FA FB 06 15 3B 1E 00 33 3B"), (Command.OPEN, 1, "FA FB 06 01 3B 01 00 02 3B"),
    (Command.CLOSE, 1, "FA FB 06 02 3B 01 00 03 3B"), (Command.ENABLE, 0, "FA FB 06 04 3B 00 00 04 3B"),
    (Command.SETO, None, "FA FB 03 07 00 07"), (Command.STOP, None, "FA FB 03 1D 00 1D"),
    (Command.RVEL, -30, "FA FB 06 15 1B 1E 00 33 1B"), (Command.SETV, 500, "FA FB 06 06 3B F4 01 FA 3C"),
    (Command.SETRV, 100, "FA FB 06 0A 3B 64 00 6E 3B"), (Command.SETA, 300, "FA FB 06 05 3B 2C 01 31 3C"),
    (Command.SETA, -300, "FA FB 06 05 1B 2C 01 31 1C"), (Command.SONAR, 0, "FA FB 06 1C 3B 00 00 1C 3B"),
    (Command.HOSTBAUD, 4, "FA FB 06 32 3B 04 00 36 3B"),
]


@pytest.mark.parametrize(("command", "arg", "wire"), VECTORS)
def test_reference_vectors_build_and_parse(command, arg, wire):
    data = bytes.fromhex(wire)
    assert build_packet(command, arg) == data
    packet = arcos.parse_packet(data)
    assert packet.id == command and arcos.parse_arg(packet.payload) == arg


def test_string_argument_round_trip():
    packet = arcos.parse_packet(build_packet(Command.CONFIG, "hello"))
    assert arcos.parse_arg(packet.payload) == "hello"


def test_checksum_odd_length_xors_last_byte():
    assert arcos.checksum(bytes([0x01, 0x02, 0x03])) == 0x0102 ^ 0x03
    assert arcos.checksum(bytes([0xFF, 0xFF, 0x00, 0x02])) == 0x0001  # 16-bit wrap


@pytest.mark.parametrize(("data", "field"), [
    (b"\xfa\xfc\x03\x00\x00\x00", "header"),
    (b"\xfa\xfb\x02\x00\x00", "count"),
    (b"\xfa\xfb\x03\x00\x00", "count"),
    (b"\xfa\xfb\x06\x0b\x3b\xc8\x00\xd3\x3c", "checksum"),
])
def test_bad_packets_name_the_field(data, field):
    with pytest.raises(ArcosError, match=field) as caught:
        arcos.parse_packet(data)
    assert caught.value.field == field


def test_bad_arguments_are_refused():
    with pytest.raises(ArcosError, match="argument"):
        build_packet(Command.VEL, 70000)
    with pytest.raises(ArcosError, match="argument"):
        build_packet(Command.VEL, 1.5)
    with pytest.raises(ArcosError, match="argument"):
        arcos.parse_arg(b"\x3c\x01\x00")


def sample_sip(**changes) -> arcos.Sip:
    fields = dict(moving=True, x_raw=0x7FF0, y_raw=12, theta_rad=math.radians(90), left_mm_s=-100,
                  right_mm_s=300, battery_v=12.7, left_stall=True, right_stall=False, front_bumpers=0b101,
                  rear_bumpers=0b1000000, control_rad=math.radians(-45), motors_enabled=True,
                  sonar_mm=((3, 1500), (7, 250)))
    fields.update(changes)
    return arcos.Sip(**fields)


def test_sip_round_trip_keeps_every_field():
    sip = sample_sip()
    parsed = arcos.parse_sip(arcos.parse_packet(arcos.encode_sip(sip)))
    assert parsed.theta_rad == pytest.approx(sip.theta_rad, abs=2 * math.pi / 4096)
    assert parsed.control_rad == pytest.approx(sip.control_rad, abs=2 * math.pi / 4096)
    assert parsed == arcos.Sip(**{**sip.__dict__, "theta_rad": parsed.theta_rad, "control_rad": parsed.control_rad})
    assert parsed.speed_mm_s == 100 and parsed.turn_rate_rad_s == pytest.approx(200 * 0.0056)
    assert parsed.stalled


def test_sip_by_hand_bytes():
    """The SIP offsets of the Operations Manual, written out: type 0x32, XPOS 0x8005 (bit 15 ignored), THPOS 1024."""
    body = bytes([0x32]) + (0x8005).to_bytes(2, "little") + (7).to_bytes(2, "little") + (1024).to_bytes(2, "little")
    body += (-5).to_bytes(2, "little", signed=True) + (5).to_bytes(2, "little", signed=True) + bytes([121])
    body += (0x0100).to_bytes(2, "little") + (0).to_bytes(2, "little") + (0x0001).to_bytes(2, "little") + bytes([0, 0])
    sip = arcos.parse_sip(arcos.parse_packet(arcos.frame(body)))
    assert (sip.moving, sip.x_raw, sip.y_raw) == (False, 5, 7)
    assert sip.theta_rad == pytest.approx(math.pi / 2)
    assert (sip.left_mm_s, sip.right_mm_s, sip.battery_v) == (-5, 5, pytest.approx(12.1))
    assert (sip.left_stall, sip.right_stall, sip.motors_enabled) == (False, True, True)


def test_short_or_wrong_sips_are_refused():
    with pytest.raises(ArcosError, match="sip length"):
        arcos.parse_sip(arcos.Packet(0x32, b"\x00" * 10))
    with pytest.raises(ArcosError, match="sip type"):
        arcos.parse_sip(arcos.Packet(arcos.CONFIG_PACKET, b"\x00" * 30))
    truncated = arcos.parse_packet(arcos.encode_sip(sample_sip()))
    with pytest.raises(ArcosError, match="sip sonar"):
        arcos.parse_sip(arcos.Packet(truncated.id, truncated.payload[:-7]))  # 5 I/O bytes, then 2 of a sonar


def test_sync2_and_dist_conv_factor():
    identity = arcos.RobotIdentity("Pioneer", "Pioneer", "p3dx-sh")
    assert arcos.parse_sync2(arcos.encode_sync2(identity)) == identity
    assert arcos.dist_conv_factor("p3dx-sh") == 1.0 and arcos.dist_conv_factor("P3AT-SH") == 1.0
    assert arcos.dist_conv_factor("p3dx") == 0.485 and arcos.dist_conv_factor("p3at") == 0.465
    with pytest.raises(ArcosError, match="subtype"):
        arcos.dist_conv_factor("roomba")
    with pytest.raises(ArcosError, match="sync2"):
        arcos.parse_sync2(b"Pioneer\x00p3dx")


def test_odometry_unwraps_15_bit_wraps_both_ways():
    unwrap = arcos.OdometryUnwrapper(0.485)
    assert unwrap.update(0x7F00, 10) == pytest.approx((0x7F00 * 0.485, 10 * 0.485))
    # x forward over the top of the 15 bits, y backward under zero
    assert unwrap.update(0x0010, 0x7FF0) == pytest.approx((0x8010 * 0.485, -0x10 * 0.485))
    assert unwrap.update(0x7FF0, 0x0005)[0] == pytest.approx(0x7FF0 * 0.485)  # and back again
    assert unwrap.update(0x7FF0, 0x0005)[1] == pytest.approx(5 * 0.485)


def test_reader_splits_chunks_and_skips_garbage():
    packets = [build_packet(Command.VEL, 200), build_packet(Command.HEAD, 90), arcos.encode_sip(sample_sip())]
    stream = b"\x00\xfa\x11" + packets[0] + b"\xfa\xfb\x06\x0b\x3b\xc8\x00\xd3\x00" + packets[1] + b"junk" + packets[2]
    reader, got = PacketReader(), []
    for i in range(0, len(stream), 3):
        got += reader.feed(stream[i:i + 3])
    assert [arcos.frame(bytes([p.id]) + p.payload) for p in got] == packets
    assert reader.skipped_bytes == 3 + 9 + 4


# --- garbled streams ---------------------------------------------------------------------------------

# (tests/onboard/test_fuzz.py runs the property on generated streams.)

def test_the_fuzz_check_catches_a_reader_that_stays_out_of_step(monkeypatch):
    """The property is not vacuous: a reader that gives up on its buffer after a bad packet fails it."""
    class GivesUp(PacketReader):
        def _skip(self, n: int) -> None:
            if n:
                self._buffer.clear()

    monkeypatch.setattr(arcos_fuzz, "PacketReader", GivesUp)
    arcos_fuzz.check_stream(b"", [])  # nothing bad happened: fine
    with pytest.raises(AssertionError, match="no resync"):
        arcos_fuzz.check_stream(b"\xfa\xfb\x05\x00", [])
