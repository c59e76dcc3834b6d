"""The Pioneer benchmark over the emulator: its figures exist and meet their targets."""

from __future__ import annotations

import pytest

from onboard.emulators.pioneer import PioneerEmulator, PioneerEmulatorConfig, PioneerServerState
from onboard.hardware import bench


@pytest.mark.integration
def test_bench_over_the_emulator_meets_its_targets(room_base):
    with PioneerEmulator(PioneerServerState(room_base(), PioneerEmulatorConfig())) as emulator:
        figures = bench.run(emulator.path, moves=3, drive_s=0.2)
    assert 0.0 < figures["command_to_wire_ms"] <= 20.0
    assert 0.0 < figures["stop_to_wire_ms"] <= 20.0
    assert 0.0 < figures["sip_parse_us"] <= 20.0 * 5  # the target is 20 µs; a loaded CI machine gets slack
