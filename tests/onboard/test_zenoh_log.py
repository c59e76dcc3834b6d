"""Which of Zenoh's log lines reach the agent's log: refusals yes, permissions worked out in advance no."""

from __future__ import annotations

import logging

from onboard.zenoh_log import ZenohLogFilter

ACL = "zenoh::net::routing::interceptor::access_control"
OBS = "cfea on Interface(lo)+CertCommonName(observer)+Transport(Tls)+cfea"


def _line(level: str, target: str, message: str, thread: str = "acc-0 ThreadId(06)") -> str:
    return f"\x1b[2m2026-11-22T17:26:02.166199Z\x1b[0m \x1b[35m{level}\x1b[0m {thread} \x1b[2m{target}\x1b[0m\x1b[2m:\x1b[0m {message}\n"


def _kept(lines: list[str]) -> list[tuple[int, str]]:
    keep = ZenohLogFilter()
    return [(entry.level, entry.message) for line in lines if (entry := keep.feed(line)) is not None]


def test_a_refused_handshake_is_a_warning_without_zenohs_misleading_hint():
    kept = _kept([_line("WARN", "zenoh_link_tls::unicast",
                        "invalid peer certificate: BadSignature. Hint: increase the system open file limit.")])
    assert kept == [(logging.WARNING, "zenoh_link_tls::unicast: TLS: invalid peer certificate: BadSignature.")]


def test_accepted_tls_peers_are_named_and_other_debug_lines_dropped():
    kept = _kept([_line("DEBUG", "zenoh_link_tls::utils", "Loading user-generated certificates."),
                  _line("DEBUG", "zenoh_link_tls::unicast", "Accepted TLS connection on 127.0.0.1:1: 127.0.0.1:2. "
                        "Common Name: planner.")])
    assert len(kept) == 1 and kept[0][0] == logging.INFO and "Common Name: planner" in kept[0][1]


def test_permissions_worked_out_in_advance_are_not_drops_but_real_drops_are():
    advance = [_line("TRACE", ACL, "ACL (egress): caching permissions for `syt/r1/move` ..."),
               _line("TRACE", ACL, f"{OBS} is unauthorized to Query (egress) on syt/r1/move"),
               _line("TRACE", ACL, f"{OBS} is unauthorized to Declare/Undeclare Queryable (egress) on syt/r1/move")]
    dropped = _line("TRACE", ACL, f"{OBS} is unauthorized to Declare Queryable (egress) on syt/r1/move")
    cached = _line("TRACE", ACL, "Using cached result: cfea is unauthorized to Put (ingress) on syt/r1/heartbeat",
                   thread="rx-0 ThreadId(12)")
    allowed = _line("TRACE", ACL, "Using cached result: cfea is authorized to Put (egress) on syt/r1/odometry")
    kept = _kept([*advance, dropped, cached, allowed])
    assert [message for _, message in kept] == [
        "access control dropped Declare Queryable (egress) on syt/r1/move "
        "(peer Interface(lo)+CertCommonName(observer)+Transport(Tls)+cfea)",
        "access control dropped Put (ingress) on syt/r1/heartbeat (peer cfea)"]


def test_a_peer_matching_no_subject_is_a_warning():
    kept = _kept([_line("INFO", ACL, "7cf1 did not match any configured ACL subject. Default permission `Deny` "
                        "will be applied on all messages")])
    assert kept and kept[0][0] == logging.WARNING and "did not match any configured ACL subject" in kept[0][1]


def test_unparsable_lines_are_ignored():
    assert _kept(["plain text\n", "\n", _line("INFO", "zenoh::net::runtime", "Using ZID: c611")]) == []
