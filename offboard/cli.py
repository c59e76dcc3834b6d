"""``syt-offboard``: the planner's side.

    syt-offboard tour --connect ENDPOINT --out DIR     drive a short scripted tour and save the images
    syt-offboard demo [--out DIR]                      start a simulated robot and run the tour on it
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from shared.transport import TransportConfig, add_transport_args, transport_from_args

log = logging.getLogger("syt.offboard")


def _tour(args: argparse.Namespace) -> int:
    return _run_tour(transport_from_args(args), args.out)


def _run_tour(transport: TransportConfig, out_dir: Path) -> int:
    from offboard.robot_client import RobotClient
    from offboard.tour import run_tour

    with transport.open() as session, RobotClient(session, transport.robot_id) as robot:
        paths = run_tour(robot, out_dir)
    log.info("wrote %d files to %s", len(paths), out_dir)
    return 0


def _demo(args: argparse.Namespace) -> int:
    from shared.launch import onboard_agent

    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with onboard_agent(["--backend", "sim", "--world", args.world], out / "onboard.log") as agent:
        transport = TransportConfig(robot_id="syt", connect=(agent.endpoint,), multicast_scouting=False)
        code = _run_tour(transport, out / "images")
    sys.stdout.write(
        f"demo finished in {time.monotonic() - started:.1f} s\n"
        f"  stereo pairs and metadata: {out / 'images'}\n"
        f"  onboard agent log:        {out / 'onboard.log'}\n")
    return code


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="syt-offboard", description="The planner side of syt.")
    parser.add_argument("-v", "--verbose", action="store_true")
    sub = parser.add_subparsers(dest="command", required=True)
    tour = sub.add_parser("tour", help="drive a short scripted tour and save the captures")
    add_transport_args(tour)
    tour.add_argument("--out", type=Path, default=Path("tour-out"), metavar="DIR")
    tour.set_defaults(func=_tour)
    demo = sub.add_parser("demo", help="start a simulated robot and drive it (two processes, loopback)")
    demo.add_argument("--world", default="paper-lab")
    demo.add_argument("--out", type=Path, default=Path("demo-out"), metavar="DIR")
    demo.set_defaults(func=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
