"""The onboard decoders under fuzzing: a short run of each (tests/offboard/fuzz runs the module's JSON)."""

import pytest

from onboard.fuzz import onboard_targets
from shared.fuzzing import run_target


@pytest.mark.parametrize("target", onboard_targets(), ids=lambda t: t.name)
def test_onboard_decoders_pass_a_short_fuzz(target):
    report = run_target(target, 60)
    assert report.cases >= 60
    assert report.failures == 0, report.examples


def test_a_broken_parser_is_reported_not_raised(monkeypatch):
    from onboard.hardware import ptu_fuzz

    (target,) = [t for t in onboard_targets() if t.name == "ptu stream"]
    monkeypatch.setattr(ptu_fuzz, "RESYNC_EVENTS", [])  # the resync check can no longer pass
    report = run_target(target, 10)
    assert report.failures == report.cases >= 10
    assert "AssertionError" in report.examples[0]


def test_a_parser_error_escaping_a_stream_is_a_failure_not_a_refusal(monkeypatch):
    """The stream targets took the parser's own error for the expected refusal, so a parser that
    raised on garbled bytes passed the fuzz."""
    from onboard.hardware import arcos
    from onboard.hardware.arcos import ArcosError

    def raising(self, data):
        raise ArcosError("a packet the reader should have skipped")
    monkeypatch.setattr(arcos.PacketReader, "feed", raising)
    (target,) = [t for t in onboard_targets() if t.name == "arcos stream"]
    report = run_target(target, 10)
    assert report.failures == report.cases >= 10 and "ArcosError" in report.examples[0]
