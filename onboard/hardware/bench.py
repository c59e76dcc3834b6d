"""How fast the Pioneer driver puts commands on the wire, and how fast it parses a SIP.

``run(port)`` drives a base on ``port`` (the emulator's pseudo-terminal in CI) through short moves
that it stops early, and reports medians: ``command_to_wire_ms`` (``move`` called → first VEL,
RVEL or HEAD bytes written), ``stop_to_wire_ms`` (``stop`` called → VEL 0 written) and
``sip_parse_us`` (one SIP through the stream reader and the parser). Targets: ≤ 20 ms, ≤ 20 ms,
≤ 20 µs.
"""

from __future__ import annotations

import statistics
import threading
import time
from collections.abc import Callable

from onboard.config import PioneerConfig
from onboard.hardware import arcos
from onboard.hardware.pioneer import PioneerBase, WireTimes
from shared.geometry import Pose2D
from shared.limits import BaseLimits

_SAMPLE_SIP = arcos.Sip(True, 0x1234, 0x0567, 1.0, 180, 220, 12.6, False, False, 0, 0, 1.0, True)


def sip_parse_us(repeats: int = 5000) -> float:
    """Median microseconds to take one SIP's bytes through ``PacketReader`` and ``parse_sip``."""
    data, reader, times = arcos.encode_sip(_SAMPLE_SIP), arcos.PacketReader(), []
    for _ in range(repeats):
        started = time.perf_counter()
        for packet in reader.feed(data):
            arcos.parse_sip(packet)
        times.append(time.perf_counter() - started)
    return statistics.median(times) * 1e6


def run(port: str, limits: BaseLimits = BaseLimits(), moves: int = 10, drive_s: float = 0.3) -> dict:
    """Medians over ``moves`` drives of 0.3 m, each stopped after ``drive_s``, back and forth."""
    base = PioneerBase(PioneerConfig(port=port), limits, Pose2D(0.0, 0.0, 0.0))
    to_wire, stop_to_wire = [], []
    try:
        for i in range(moves):
            to_wire_s, stop_s = _stopped_move(base, 0.3 if i % 2 == 0 else -0.3, drive_s)
            to_wire.append(to_wire_s)
            stop_to_wire.append(stop_s)
    finally:
        base.close()
    return {"command_to_wire_ms": round(statistics.median(to_wire) * 1e3, 3),
            "stop_to_wire_ms": round(statistics.median(stop_to_wire) * 1e3, 3),
            "sip_parse_us": round(sip_parse_us(), 3), "moves": moves, "port": port}


def _stopped_move(base: PioneerBase, distance_m: float, drive_s: float) -> tuple[float, float]:
    """One move stopped after ``drive_s``; (move → wire, stop → wire) in seconds."""
    outcome: list = []
    mover = threading.Thread(target=lambda: outcome.append(base.move(0.0, distance_m, 0.3, threading.Event())))
    previous_call = base.wire_times.move_called_s
    mover.start()
    # stop a move already on the wire: a thread slow to start could otherwise begin after the stop
    _wait(lambda: _on_wire(base.wire_times, previous_call) or not mover.is_alive(), 3.0, 0.002)
    time.sleep(drive_s)
    base.stop()
    mover.join(timeout=5.0)
    times = base.wire_times
    if not outcome or times.move_wire_s is None or times.stop_wire_s is None:
        raise RuntimeError("the benchmark's move did not reach the wire; is the base connected?")
    _wait(lambda: not base.reading().moving, 3.0, 0.02)
    return times.move_wire_s - times.move_called_s, times.stop_wire_s - times.stop_called_s


def _on_wire(times: WireTimes, previous_call: float | None) -> bool:
    """Whether the move called after ``previous_call`` has written its first motion command."""
    return times.move_called_s != previous_call and times.move_wire_s is not None


def _wait(done: Callable[[], bool], timeout_s: float, poll_s: float) -> None:
    """Poll ``done`` until it holds or ``timeout_s`` has passed; the caller judges what it finds."""
    deadline = time.monotonic() + timeout_s
    while not done() and time.monotonic() < deadline:
        time.sleep(poll_s)
