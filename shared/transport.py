"""Zenoh transport options shared by both programs, parsed by one helper.

Both ``syt-onboard`` and ``syt-offboard`` take ``--robot ID``, ``--connect ENDPOINT``,
``--listen ENDPOINT``, ``--zenoh-config FILE.json5``, ``--mode peer|client`` and
``--no-multicast-scouting``. Peer mode is the default: two processes talk directly, no router.
"""

from __future__ import annotations

import argparse
import json
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import zenoh

from shared.arguments import number
from shared.config import ConfigError
from shared.keys import check_robot_id

log = logging.getLogger(__name__)

# A frozen or unplugged peer is declared gone after this lease (Zenoh's default is 10 s): the robot
# must notice a lost planner quickly, since its watchdog acts on the liveliness token.
DEFAULT_LEASE_MS = 2000
LEASE_MS_RANGE = (100, 3_600_000)
_LEASE = "transport/link/tx/lease"
# Sessions connect where they are told to (listen, connect) or by multicast scouting, not to every
# peer gossip names: with Zenoh's default the agent kept dialling each short-lived observer's
# addresses after it had left (6,482 attempts for 400 observers), and beside three busy loops a
# planner's query went unanswered for 5 s, observers' queries reached nobody, and a close timed out.
# With autoconnect off, none of that in 1,100 observers, nor any dialling.
# Gossip itself stays on (Zenoh warns without it). A file that sets any gossip setting keeps its own.
_GOSSIP = "scouting/gossip"


@dataclass(frozen=True)
class TransportConfig:
    robot_id: str = "syt"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    zenoh_config: Path | None = None
    # None leaves these to the file (or Zenoh's default); a flag given on the command line overrides the file
    mode: Literal["peer", "client"] | None = None
    multicast_scouting: bool | None = None
    lease_ms: int | None = None  # None: the file's lease, or DEFAULT_LEASE_MS where the file sets none
    extra: dict = field(default_factory=dict)  # further "key/path": json-value overrides

    def __post_init__(self) -> None:
        check_robot_id(self.robot_id)
        if self.lease_ms is not None and not LEASE_MS_RANGE[0] <= self.lease_ms <= LEASE_MS_RANGE[1]:
            # Zenoh takes any lease: 0 dropped every peer at once, and the agent "lost" its planner 4 ms in
            raise ValueError(f"--lease-ms must lie in [{LEASE_MS_RANGE[0]}, {LEASE_MS_RANGE[1]}], got {self.lease_ms}")

    def zenoh(self) -> zenoh.Config:
        """The Zenoh configuration: the file first, then what the flags say on top."""
        if self.zenoh_config is not None:
            if not self.zenoh_config.is_file():
                raise FileNotFoundError(f"--zenoh-config: no such file {self.zenoh_config}")
            try:
                config = zenoh.Config.from_file(str(self.zenoh_config))
            except zenoh.ZError as exc:  # Zenoh's message points at a line, not at the file
                raise ConfigError("--zenoh-config", str(self.zenoh_config),  # the value shown may be cut short
                                  f"{self.zenoh_config} is not a Zenoh configuration: {exc}") from None
        else:
            config = zenoh.Config()
        for key, value in {**self._flag_settings(config), **self.extra}.items():
            config.insert_json5(key, json.dumps(value))
        return config

    def _flag_settings(self, config: zenoh.Config) -> dict:
        """The flags that were given, plus the project's lease and gossip where the file keeps Zenoh's."""
        zenohs = zenoh.Config()
        lease = self.lease_ms
        if lease is None and config.get_json(_LEASE) == zenohs.get_json(_LEASE):
            lease = DEFAULT_LEASE_MS
        gossip = {"router": [], "peer": []} if config.get_json(_GOSSIP) == zenohs.get_json(_GOSSIP) else None
        settings = {"mode": self.mode, "scouting/multicast/enabled": self.multicast_scouting, _LEASE: lease,
                    f"{_GOSSIP}/autoconnect": gossip,
                    "connect/endpoints": list(self.connect) or None, "listen/endpoints": list(self.listen) or None}
        return {key: value for key, value in settings.items() if value is not None}

    def open(self, config: zenoh.Config | None = None) -> zenoh.Session:
        """A session on ``config`` where the caller has built (and checked) it already, so that the session
        runs on what was checked and not on a second reading of a file that may have changed since."""
        log.info("opening Zenoh session: mode=%s connect=%s listen=%s scouting=%s",
                 self.mode, list(self.connect), list(self.listen), self.multicast_scouting)
        return zenoh.open(self.zenoh() if config is None else config)


def add_transport_args(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("transport (Zenoh)")
    group.add_argument("--robot", metavar="ID", help="robot id: keys live under syt/<ID>/ (default: syt; on a resume, the saved one)")
    group.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                       help="endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable)")
    group.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                       help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    group.add_argument("--zenoh-config", type=Path, metavar="FILE.json5",
                       help="a Zenoh configuration file (TLS, access control ...); flags override it")
    group.add_argument("--mode", choices=("peer", "client"), help="Zenoh mode (default: the file's, else peer)")
    group.add_argument("--no-multicast-scouting", action="store_true",
                       help="do not discover peers by multicast (use with --connect/--listen)")
    group.add_argument("--lease-ms", type=number("--lease-ms", *LEASE_MS_RANGE, kind=int),
                       help=f"link lease: a silent peer is dropped after this (default: the file's, else {DEFAULT_LEASE_MS})")


def transport_from_args(args: argparse.Namespace, saved: TransportConfig = TransportConfig()) -> TransportConfig:
    """``saved`` (by default the defaults) with each flag given in its place: a resumed search keeps
    its saved robot and TLS file when only ``--connect`` is given anew."""
    given = {"robot_id": args.robot, "connect": tuple(args.connect) or None, "listen": tuple(args.listen) or None,
             "zenoh_config": args.zenoh_config, "mode": args.mode,
             "multicast_scouting": False if args.no_multicast_scouting else None, "lease_ms": args.lease_ms}
    return replace(saved, **{name: value for name, value in given.items() if value is not None})
