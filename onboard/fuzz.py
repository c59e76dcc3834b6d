"""The onboard decoders under fuzzing: the ARCOS and PTU-D46 serial parsers and the agent's config.

    python -m onboard.fuzz --cases N [--json] [--only NAME]

The serial parsers keep their own generators and properties (``onboard.hardware.arcos_fuzz``,
``ptu_fuzz``: garbled streams, any chunking, resync afterwards); here they run through the shared
runner, which counts failures instead of stopping at the first. ``syt-offboard fuzz`` runs this
module as a subprocess (the planner side may not import onboard) and merges its JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import ModuleType

from shared.fuzzing import Case, FuzzTarget, MissingHypothesis, require_hypothesis

DEPLOY_CONFIG = Path(__file__).resolve().parent.parent / "deploy" / "robot" / "onboard.toml"


class StreamRaisedNothing(Exception):
    """The error a stream target "refuses" with, which nothing raises: feeding a serial parser any
    stream must raise nothing, so its own error escaping is a failure, not a refusal."""


def _stream_target(name: str, fuzz_module: ModuleType) -> FuzzTarget:
    """A serial parser's own property as a target: ``check_stream`` raises on any failure."""
    from hypothesis import strategies as st

    def cases():
        return st.tuples(fuzz_module.garbled_streams(), st.lists(st.integers(0, 10_000), max_size=8)).map(
            lambda sc: Case(sc, None, False, "garbled stream"))
    return FuzzTarget(name, cases, lambda sc: fuzz_module.check_stream(*sc), StreamRaisedNothing)


def onboard_targets() -> list[FuzzTarget]:
    from onboard.config import OnboardConfig
    from onboard.hardware import arcos_fuzz, ptu_fuzz
    from shared import toml_writer
    from shared.config import ConfigError, load_config
    from shared.fuzz_targets import toml_target
    from shared.strict import to_plain

    texts = [toml_writer.dumps(to_plain(OnboardConfig()))]
    if DEPLOY_CONFIG.is_file():  # a source checkout: the shipped robot config too
        texts.append(DEPLOY_CONFIG.read_text())
    return [
        _stream_target("arcos stream", arcos_fuzz),
        _stream_target("ptu stream", ptu_fuzz),
        toml_target("onboard config toml", lambda p: load_config(OnboardConfig, p), ConfigError, texts,
                    OnboardConfig),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m onboard.fuzz", description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1000, help="cases per decoder")
    parser.add_argument("--only", action="append", default=[], metavar="NAME", help="decoders whose name contains NAME")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    try:
        require_hypothesis()
    except MissingHypothesis as exc:
        sys.stderr.write(f"{exc}\n")
        return 2
    from shared.fuzzing import run_targets, summary, table

    reports = run_targets(onboard_targets(), args.cases, tuple(args.only))
    sys.stdout.write((json.dumps(summary(reports, args.cases)) if args.json else table(reports)) + "\n")
    return 1 if any(r.failures for r in reports) else 0


if __name__ == "__main__":
    sys.exit(main())
