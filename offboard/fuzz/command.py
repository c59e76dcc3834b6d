"""``syt-offboard fuzz``: every decoder, or (``--live``) a running agent.

    syt-offboard fuzz --cases N [--json] [--only NAME] [--jobs J]
    syt-offboard fuzz --live --cases N [--json] [--connect ENDPOINT --robot ID]

The decoders of shared and of this side run here (``--jobs`` processes), the onboard ones at the
same time in ``python -m onboard.fuzz`` (this side may not import onboard); their reports are
merged into one. The live fuzz starts its own simulated agent on loopback unless ``--connect``
names one. Exits 1 on any failure, 2 without hypothesis (a test extra: the message says how to
install it).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import logging
import subprocess
import sys
import tempfile
from pathlib import Path

from shared.fuzzing import FuzzReport, MissingHypothesis, require_hypothesis

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from shared.transport import add_transport_args

    parser.add_argument("--cases", type=int, default=10_000, help="cases per decoder, or queries with --live")
    parser.add_argument("--only", action="append", default=[], metavar="NAME",
                        help="only the decoders whose name contains NAME (repeatable)")
    parser.add_argument("--jobs", type=int, default=1, help="processes for this side's decoders")
    parser.add_argument("--live", action="store_true", help="fuzz a running agent over Zenoh instead")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    add_transport_args(parser)


def main(args: argparse.Namespace) -> int:
    try:
        require_hypothesis()
    except MissingHypothesis as exc:
        sys.stderr.write(f"syt-offboard fuzz: {exc}\n")
        return 2
    return _live(args) if args.live else _decoders(args)


# --- decoders --------------------------------------------------------------------------------------

def _decoders(args: argparse.Namespace) -> int:
    from shared.fuzzing import summary, table

    onboard = subprocess.Popen(
        [sys.executable, "-m", "onboard.fuzz", "--cases", str(args.cases), "--json",
         *[a for name in args.only for a in ("--only", name)]],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    reports = _run_here(args.cases, tuple(args.only), args.jobs)
    out, err = onboard.communicate()
    reports += _onboard_reports(out, err, onboard.returncode)
    sys.stdout.write((json.dumps(summary(reports, args.cases)) if args.json else table(reports)) + "\n")
    return 1 if any(r.failures or r.cases < args.cases for r in reports) else 0


def _run_here(cases: int, only: tuple[str, ...], jobs: int) -> list[FuzzReport]:
    from offboard.fuzz.targets import in_process_targets
    from shared.fuzz_targets import unsampled_types

    names = [t.name for t in in_process_targets() if not only or any(o in t.name for o in only)]
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        reports = [FuzzReport(**r) for r in pool.map(_run_one, names, [cases] * len(names))]
    return reports + [FuzzReport(f"message {name}", failures=1,
                                 examples=[f"no valid {name} in shared.fuzz_targets.SAMPLES: not fuzzed"])
                      for name in unsampled_types()]


def _run_one(name: str, cases: int) -> dict:
    """One target in a worker process (targets hold lambdas: they are rebuilt, not pickled)."""
    import cv2

    from offboard.fuzz.targets import in_process_targets
    from shared.fuzzing import run_target

    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # broken PNGs are the point
    (target,) = [t for t in in_process_targets() if t.name == name]
    return run_target(target, cases).to_json()


def _onboard_reports(out: str, err: str, returncode: int) -> list[FuzzReport]:
    try:
        return [FuzzReport(**r) for r in json.loads(out)["decoders"]]
    except (ValueError, KeyError, TypeError):
        return [FuzzReport("onboard fuzz", failures=1,
                           examples=[f"python -m onboard.fuzz exited with {returncode}: {err[-1500:]}"])]


# --- live ------------------------------------------------------------------------------------------

def _live(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from offboard.fuzz.live import run_live
    from shared.launch import onboard_agent
    from shared.transport import TransportConfig, transport_from_args

    if args.connect:
        transport = transport_from_args(args)
        with transport.open() as session:
            report = run_live(session, transport.robot_id, args.cases)
    else:
        with tempfile.TemporaryDirectory() as tmp, \
                onboard_agent(["--backend", "sim", "--world", "paper-lab"], Path(tmp) / "onboard.log") as agent:
            transport = TransportConfig(robot_id="syt", connect=(agent.endpoint,), multicast_scouting=False)
            with transport.open() as session:
                agent.wait_ready(session, "syt")
                report = run_live(session, "syt", args.cases)
            report.agent_alive = agent.process.poll() is None
            report.agent_tracebacks = (Path(tmp) / "onboard.log").read_text().count("Traceback")
    sys.stdout.write(json.dumps(asdict(report) | {"ok": report.ok}) + "\n")
    return 0 if report.ok else 1
