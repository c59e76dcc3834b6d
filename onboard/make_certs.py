"""``syt-onboard make-certs --out DIR``: the certificates of a robot's mutual TLS and the Zenoh configs using them.

    syt-onboard make-certs --out DIR [--host NAME ...] [--days N] [--cert-dir PATH] [--force]

Writes ``onboard.certificates``'s files and ``zenoh-robot.json5``, ``zenoh-planner.json5`` and
``zenoh-observer.json5`` (``onboard.secure_transport``), ready for ``--zenoh-config``. The configs name the
certificates by ``--cert-dir`` (default: DIR itself), the place they will be read from on each machine.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from onboard.certificates import DEFAULT_DAYS, MAX_DAYS, make_certificates, robot_hosts
from onboard.secure_transport import write_configs

log = logging.getLogger("syt.onboard")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="syt-onboard make-certs",
                                     description="Make a CA, robot and role certificates, and Zenoh configs using them.")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="where to write them")
    parser.add_argument("--host", action="append", default=[], metavar="NAME",
                        help="a name or address the workstation dials the robot by, added to the robot "
                             "certificate beside localhost and 127.0.0.1 (repeatable; the first goes in the "
                             "planner's and observer's connect endpoint)")
    parser.add_argument("--days", type=int, default=DEFAULT_DAYS, help=f"validity (default: {DEFAULT_DAYS})")
    parser.add_argument("--cert-dir", type=Path, metavar="PATH",
                        help="where the configs say the certificates are, e.g. /etc/syt/certs (default: DIR)")
    parser.add_argument("--force", action="store_true", help="replace an existing CA in DIR")
    return parser


def run(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    if (args.out / "ca.key").exists() and not args.force:
        log.error("%s exists: certificates signed by it would stop working; --force replaces it",
                  args.out / "ca.key")
        return 2
    try:
        robot_hosts(args.host)
        if not 0 < args.days <= MAX_DAYS:
            raise ValueError(f"--days must be 1 to {MAX_DAYS}, not {args.days}")
    except ValueError as exc:
        log.error("%s", exc)
        return 2
    issued = make_certificates(args.out, args.host, args.days)
    cert_dir = args.cert_dir or args.out.resolve()
    configs = write_configs(args.out, cert_dir, (args.host or ["localhost"])[0])
    for path in [*(args.out / f"{stem}.pem" for stem in issued), *configs]:
        sys.stdout.write(f"{path}\n")
    return 0
