"""``syt-offboard``: the planner's side.

    syt-offboard search --connect ENDPOINT --target-picture P --target-size X,Y,Z --out DIR [...]
    syt-offboard demo [--world paper-lab] [--out demo-out]   a simulated robot and a search, two processes
    syt-offboard tour --connect ENDPOINT --out DIR           a short scripted drive, saving the images
    syt-offboard bench perception|planner|navigation|checkpoint --json
    syt-offboard bench safety --json [--load] [--trials N]  stop latencies when the planner is lost
    syt-offboard bench stereo --views DIR --json           SAD and SGBM on rendered views of rooms
    syt-offboard calibrate-detector --detector sift --target-picture P --out TABLE.json
    syt-offboard experiment --preset paper --out DIR [--baselines] [--jobs N]
    syt-offboard compare BASE_DIR NEW_DIR [--json]  two sweeps of one grid, paired run for run
    syt-offboard fuzz --cases N [--json]            every decoder; --live: malformed queries to an agent
    syt-offboard compile                            the numba kernels into numba's cache (make does it once)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path

from shared.arguments import floats, number, probability
from shared.config import ConfigError
from shared.transport import DEFAULT_LEASE_MS, TransportConfig, add_transport_args, transport_from_args

log = logging.getLogger("syt.offboard")


# --- search ----------------------------------------------------------------------------------------

def _prior(spec: str) -> str:
    from offboard.search.loop import check_prior_spec

    try:
        return check_prior_spec(spec)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _budget(text: str) -> float:
    """``--budget-s``, in the range the configuration file's ``planner.budget_s`` must lie in."""
    from offboard.planning.planner import PlannerConfig  # here: importing the planner costs every command

    lo, hi = next(f.metadata["bounds"] for f in dataclasses.fields(PlannerConfig) if f.name == "budget_s")
    return number("--budget-s", lo, hi)(text)


def _detectability(spec: str) -> str:
    """``NAME=FILE``: a detector's name and a table it loads, checked before anything connects."""
    from offboard.perception.detectability import DetectabilityTable
    from offboard.search.run import detectability_file

    try:
        _, path = detectability_file(spec)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    try:
        DetectabilityTable.load(path)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--detectability: {exc}") from None
    return spec


def _new_file(flag: str) -> Callable[[str], Path]:
    """A file to be written: not a folder, in a folder that exists (checked before the long work)."""
    def parse(text: str) -> Path:
        path = Path(text)
        if path.is_dir() or not path.parent.is_dir():
            raise argparse.ArgumentTypeError(f"{flag} {text}: needs a file name in an existing folder")
        return path
    return parse


def _add_search_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--target-picture", action="append", type=Path, metavar="PATH",
                        help="a picture of the target's textured face (repeatable; required unless --resume)")
    parser.add_argument("--target-size", type=floats(3, "--target-size", positive=True), default=(0.23, 0.23, 0.23),
                        metavar="X,Y,Z", help="target extents in metres; the picture covers the Y × Z face")
    parser.add_argument("--target-sides", type=int, choices=(1, 4), default=1,
                        help="pictured vertical faces: 1, or 4 (seen from any direction, as the report assumes)")
    parser.add_argument("--room", type=floats(3, "--room", positive=True), metavar="X,Y,Z",
                        help="the search region's size in metres, from the floor corner at the origin "
                             "(default: the configuration's room_m, 9,5,2.5)")
    parser.add_argument("--cost", type=int, choices=(1, 2, 3, 4),
                        help="cost function (report §5.2.1; default: the configuration's, 3)")
    parser.add_argument("--prior", action="append", default=[], metavar="KIND", type=_prior,
                        help="uniform | hints:FILE | surfaces | saliency | last-seen:X,Y,Z[,S] (repeatable)")
    parser.add_argument("--budget-s", type=_budget, metavar="SECONDS",
                        help="robot-time budget K (default: the configuration's, 1800)")
    parser.add_argument("--move-threshold", type=probability("--move-threshold"), default=None, metavar="P",
                        help="Θ_move: move by the report's threshold rule, not the default rate rule")
    parser.add_argument("--detector", choices=("sift", "ncc", "auto"), help="default: the configuration's, sift")
    parser.add_argument("--detectability", action="append", default=[], metavar="NAME=FILE", type=_detectability,
                        help="a detector's measured detectability table (from calibrate-detector)")
    parser.add_argument("--config", type=Path, metavar="FILE.toml",
                        help="search configuration (SearchConfig); the options above override its values")
    parser.add_argument("--out", type=Path, default=Path("search-out"), metavar="DIR",
                        help="summary, looks, logs, recording and checkpoint (default: search-out)")
    parser.add_argument("--resume", type=Path, metavar="DIR",
                        help="carry on the search checkpointed in DIR with its own options (a transport flag given replaces "
                             "its saved setting)")
    parser.add_argument("--spawn", action="store_true", help="stream the recording to a new Rerun viewer")
    parser.add_argument("--connect-viewer", metavar="URL", help="stream the recording to a running Rerun viewer")


def _search(args: argparse.Namespace) -> int:
    from offboard.search.checkpoint import FILE_NAME as CHECKPOINT
    from offboard.search.run import SearchRequest, run_search

    if args.resume:
        return _resume(args)
    if not args.target_picture:
        raise SystemExit("syt-offboard search: --target-picture is required (or --resume DIR)")
    if (args.out / CHECKPOINT).exists() and not (args.out / "summary.json").exists():  # a search cut short there
        raise ConfigError("--out", str(args.out), "holds an interrupted search (a checkpoint, no summary): carry "
                                                  "it on with --resume, or choose another --out")
    request = SearchRequest(
        pictures=tuple(args.target_picture), target_size_m=args.target_size, target_sides=args.target_sides,
        room_m=args.room, cost=args.cost,
        priors=tuple(args.prior) or ("uniform",), budget_s=args.budget_s, move_threshold=args.move_threshold,
        detector=args.detector, detectability=tuple(args.detectability), config_path=args.config, out_dir=args.out,
        spawn=args.spawn, viewer_url=args.connect_viewer)
    summary = run_search(transport_from_args(args), request)
    sys.stdout.write(json.dumps(summary) + "\n")
    return 0 if summary["found"] else 3


def _resume(args: argparse.Namespace) -> int:
    """Carry on from ``--resume DIR``: the checkpoint's request and transport (each transport flag
    given replaces its saved setting), the robot's odometry continuing; the summary covers the whole
    search."""
    from offboard.search.checkpoint import CheckpointError, read
    from offboard.search.run import run_search

    given = _search_options_given(args)
    if given:
        raise ConfigError("--resume", given, "a resumed search carries on with the options it was started with: "
                                             "only transport flags may be given with it")
    try:
        checkpoint = read(args.resume)
        summary = run_search(transport_from_args(args, checkpoint.transport), checkpoint.request,
                             resume=checkpoint)
    except CheckpointError as exc:  # read, or restored into the search before the robot moves
        raise SystemExit(f"syt-offboard search --resume: {exc}") from None
    sys.stdout.write(json.dumps(summary) + "\n")
    return 0 if summary["found"] else 3


def _search_options_given(args: argparse.Namespace) -> list[str]:
    """The search options (not transport flags) that ``args`` sets off their defaults, as flags."""
    scratch = argparse.ArgumentParser(add_help=False)
    _add_search_args(scratch)
    defaults = vars(scratch.parse_args([]))
    return ["--" + dest.replace("_", "-") for dest, default in defaults.items()
            if dest != "resume" and getattr(args, dest) != default]


# --- demo and tour ---------------------------------------------------------------------------------

def _tour(args: argparse.Namespace) -> int:
    from offboard.robot.robot_client import RobotClient
    from offboard.robot.tour import run_tour

    transport = transport_from_args(args)
    with transport.open() as session, RobotClient(session, transport.robot_id) as robot:
        paths = run_tour(robot, args.out)
    log.info("wrote %d files to %s", len(paths), args.out)
    return 0


def _demo(args: argparse.Namespace) -> int:
    from offboard.experiments.world_facts import load_facts
    from offboard.search.run import SearchRequest, run_search
    from shared.launch import onboard_agent
    from shared.world import WorldError

    out: Path = args.out
    try:
        world = load_facts(args.world)  # the demo is the experimenter: it knows what the target looks like
        picture = world.picture_file(out)
    except WorldError as exc:  # a broken world, or a picture the simulator cannot draw
        log.error("--world %s: %s", args.world, exc)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with onboard_agent(["--backend", "sim", "--world", args.world], out / "onboard.log") as agent:
        transport = TransportConfig(robot_id="syt", connect=(agent.endpoint,), multicast_scouting=False)
        with transport.open() as session:
            agent.wait_ready(session, "syt")
        request = SearchRequest(pictures=(picture,), target_size_m=world.target_size_m,
                                target_sides=world.target_sides, room_m=args.room or world.room_m, cost=3,
                                priors=("uniform",), out_dir=out, spawn=args.spawn)
        summary = run_search(transport, request)
    sys.stdout.write(
        f"\nsearch {'found the target' if summary['found'] else 'ended: ' + summary['status']} in "
        f"{summary['actions']} looks, {summary['distance_m']:.1f} m, {summary['robot_time_s'] / 60:.1f} min of "
        f"robot time ({time.monotonic() - started:.0f} s here)\n"
        f"  target estimate:  {summary['target_estimate_m']}\n"
        f"  summary:          {out / 'summary.json'}\n"
        f"  top view:         {out / 'search.png'}\n"
        f"  recording:        {out / 'search.rrd'}   (open it: .venv/bin/rerun {out / 'search.rrd'})\n"
        f"  logs:             {out / 'search.log'}, {out / 'onboard.log'}\n")
    return 0 if summary["found"] else 3


# --- calibration -----------------------------------------------------------------------------------

def _calibrate(args: argparse.Namespace) -> int:
    import shutil
    import tempfile

    from offboard.perception import calibration
    from offboard.perception.detection.detector import make_detector
    from offboard.perception.detection.target_model import TargetModel
    from offboard.robot.robot_client import RobotClient
    from shared.geometry import HeadMount
    from shared.launch import onboard_agent

    model = TargetModel.from_files(args.target_picture, args.target_size)
    grid = calibration.CalibrationGrid(samples=args.samples, negatives=args.negatives)
    head_m = HeadMount().height_m  # the agent below runs the default head: the face sits at its cameras' height
    with tempfile.TemporaryDirectory() as tmp:
        world = Path(tmp) / "calibration.toml"
        shutil.copy(args.target_picture[0], Path(tmp) / "target.png")
        world.write_text(calibration.calibration_world("target.png", args.target_size, head_m))
        with onboard_agent(["--backend", "sim", "--world", str(world)], Path(tmp) / "onboard.log") as agent:
            transport = TransportConfig(robot_id="syt", connect=(agent.endpoint,), multicast_scouting=False)
            with transport.open() as session, RobotClient(session, "syt") as robot:
                agent.wait_ready(session, "syt")
                info = robot.wait_for_robot()
                detector = make_detector(args.detector, model, info.intrinsics.to_intrinsics())
                face = calibration.face_centre(args.target_size, head_m)
                tally = calibration.calibrate(robot, detector, grid, face, args.target_size[1], _progress)
    table = calibration.to_table(args.detector, grid, tally, model.face_size_m)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    table.save(args.out)
    sys.stderr.write("\n")
    sys.stdout.write(json.dumps({**calibration.summary(table, tally), "table": str(args.out)}) + "\n")
    return 0


def _progress(done: int, total: int) -> None:
    if done % 10 == 0 or done == total:
        sys.stderr.write(f"\rcalibrating: {done}/{total} views")
        sys.stderr.flush()


# --- experiments -----------------------------------------------------------------------------------

def _experiment(args: argparse.Namespace) -> int:
    from offboard.experiments import harness as experiment

    return experiment.main(args)


# --- benchmarks ------------------------------------------------------------------------------------

def _bench(args: argparse.Namespace) -> int:
    if args.what == "safety":
        from offboard.bench.safety import run

        sys.stdout.write(json.dumps(run(args.trials, args.lease_ms, args.load)) + "\n")
        return 0
    if args.what == "stereo":
        from offboard.bench.stereo import run

        if args.views is None:
            log.error("bench stereo: --views DIR is required (write them with `syt-onboard worlds views`)")
            return 2
        try:
            sys.stdout.write(json.dumps(run(args.views)) + "\n")
        except ValueError as exc:
            log.error("%s", exc)
            return 2
        return 0
    if args.what == "checkpoint":
        from offboard.bench.checkpoint import run
    elif args.what == "planner":
        from offboard.bench.planner import run
    elif args.what == "perception":
        from offboard.bench.perception import run
    else:
        from offboard.bench.navigation import run
    sys.stdout.write(json.dumps(run()) + "\n")
    return 0


# --- two sweeps compared ---------------------------------------------------------------------------

def _compare(args: argparse.Namespace) -> int:
    from offboard.experiments.comparison import compare, comparison_json, comparison_md, load_sweep

    try:
        base, new = load_sweep(args.base), load_sweep(args.new)
    except (OSError, KeyError, ValueError) as exc:  # a missing folder, or a results.csv that is not one
        log.error("compare: %s", exc)
        return 2
    result = compare(base, new, str(args.base), str(args.new))
    if not result.groups:
        log.error("compare: %s and %s have no run in common (the same method, cost, prior, world, start, "
                  "target and seed)", args.base, args.new)
        return 2
    sys.stdout.write(json.dumps(comparison_json(result)) + "\n" if args.json else comparison_md(result))
    return 0


# --- numba's cache --------------------------------------------------------------------------------

def _compile(args: argparse.Namespace) -> int:
    from offboard.kernel_cache import compile_kernels

    started = time.monotonic()
    compile_kernels()
    log.info("numba kernels ready in %.1f s", time.monotonic() - started)
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="syt-offboard", description="The planner side of syt.")
    parser.add_argument("-v", "--verbose", action="store_true")
    sub = parser.add_subparsers(dest="command", required=True)
    search = sub.add_parser("search", help="search for the target with a robot over Zenoh")
    add_transport_args(search)
    _add_search_args(search)
    search.set_defaults(func=_search)
    demo = sub.add_parser("demo", help="start a simulated robot and search with it (two processes, loopback)")
    demo.add_argument("--world", default="paper-lab", help="a bundled world or a world file (default: paper-lab)")
    demo.add_argument("--room", type=floats(3, "--room", positive=True), metavar="X,Y,Z",
                      help="the search region (default: the world's room)")
    demo.add_argument("--out", type=Path, default=Path("demo-out"), metavar="DIR", help="default: demo-out")
    demo.add_argument("--spawn", action="store_true", help="also stream to a new Rerun viewer")
    demo.set_defaults(func=_demo)
    tour = sub.add_parser("tour", help="drive a short scripted tour and save the captures")
    add_transport_args(tour)
    tour.add_argument("--out", type=Path, default=Path("tour-out"), metavar="DIR", help="default: tour-out")
    tour.set_defaults(func=_tour)
    calibrate = sub.add_parser("calibrate-detector", help="measure a detector's detectability table in simulation")
    calibrate.add_argument("--detector", choices=("sift", "ncc"), default="sift")
    calibrate.add_argument("--target-picture", action="append", type=Path, required=True, metavar="PATH")
    calibrate.add_argument("--target-size", type=floats(3, "--target-size", positive=True), default=(0.23, 0.23, 0.23), metavar="X,Y,Z")
    calibrate.add_argument("--samples", type=number("--samples", 1, 1000, int), default=1,
                           help="views per cell (the first at its centre, the second mirrored, the rest anywhere in it)")
    calibrate.add_argument("--negatives", type=number("--negatives", 0, 100_000, int), default=200,
                           help="views without the target")
    calibrate.add_argument("--out", type=_new_file("--out"), required=True, metavar="FILE.json")
    calibrate.set_defaults(func=_calibrate)
    from offboard.experiments import harness  # its options live with the harness

    experiment = sub.add_parser("experiment", help="run a grid of searches (the report's Tables 2 and 3, baselines)")
    harness.add_arguments(experiment)
    experiment.set_defaults(func=_experiment)
    comparing = sub.add_parser("compare", help="two sweeps of one grid (experiment --out folders), paired run for run")
    comparing.add_argument("base", type=Path, metavar="BASE_DIR")
    comparing.add_argument("new", type=Path, metavar="NEW_DIR")
    comparing.add_argument("--json", action="store_true", help="print one JSON object instead of Markdown")
    comparing.set_defaults(func=_compare)
    bench = sub.add_parser("bench", help="measure a part; prints one JSON object")
    bench.add_argument("what", choices=("perception", "planner", "navigation", "safety", "checkpoint", "stereo"))
    bench.add_argument("--json", action="store_true", help="print one JSON object (the only output form)")
    bench.add_argument("--trials", type=number("--trials", 1, 10_000, int), default=20,
                       help="safety: trials of each fault")
    bench.add_argument("--lease-ms", type=int, default=DEFAULT_LEASE_MS, help="safety: the Zenoh link lease")
    bench.add_argument("--load", action="store_true", help="safety: also measure under load (4 state clients)")
    bench.add_argument("--views", type=Path, metavar="DIR", help="stereo: views from `syt-onboard worlds views`")
    bench.set_defaults(func=_bench)
    from offboard.fuzz import command as fuzz  # its options live with it

    fuzzing = sub.add_parser("fuzz", help="fuzz every decoder (hypothesis), or a running agent with --live")
    fuzz.add_arguments(fuzzing)
    fuzzing.set_defaults(func=fuzz.main)
    sub.add_parser("compile", help="compile the numba kernels into numba's on-disk cache, so no search pays for "
                                   "compilation").set_defaults(func=_compile)
    return parser


def main(argv: list[str] | None = None) -> int:
    from offboard.perception.detection.target_model import TargetModelError
    from shared.codec import ProtocolError
    from shared.rpc import CommandError, RobotUnavailable

    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except (ConfigError, TargetModelError) as exc:  # a bad file or value given: named, not a traceback
        log.error("%s", exc)
        return 2
    except RobotUnavailable as exc:  # the robot never came, or was lost: its checkpoint, if any, is kept
        log.error("%s (a search that wrote a checkpoint carries on with --resume DIR)", exc)
        return 1
    except (CommandError, ProtocolError) as exc:  # the robot refused a command (busy, a limit) or garbled a reply
        log.error("the robot: %s", exc)
        return 1


if __name__ == "__main__":
    sys.exit(main())
