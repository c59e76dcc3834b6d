"""``syt-onboard``: the agent on the robot, and the robot-side tools (``syt-onboard --help`` lists them).

    syt-onboard --backend sim --world paper-lab [--start X,Y,HEADING_DEG] [--target X,Y,Z,YAW_DEG]
    syt-onboard --backend hardware --config robot.toml    the serial drivers of [hardware.*] (onboard/backends.py)
    syt-onboard render --world FILE [--start ..] [--pan DEG] [--tilt DEG] --out DIR
    syt-onboard bench [--backend hardware [--port PORT]] --json
    syt-onboard picture NAME --out FILE.png          a built-in picture (the target's) for the planner
    syt-onboard worlds generate --count N --seed S --out DIR [--max-turn-deg D]  checked rooms room-S-K.toml
    syt-onboard worlds check WORLD... [--config FILE.toml]  can the simulator run them (format, pictures, ceiling)
    syt-onboard emulate --world NAME_OR_FILE         a Pioneer and a PTU-D46 on pseudo-terminals (JSON line)
    syt-onboard calibrate-stereo --images DIR --board COLSxROWS --square-mm S --out stereo.yaml
    syt-onboard probe [--port PORT] [--json]          serial ports and cameras, and what answers on them
    syt-onboard make-certs --out DIR [--host NAME]   mutual-TLS certificates and Zenoh configs (README, Security)
    syt-onboard compile                             the simulator's renderer into numba's cache (make does it once)
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

import zenoh

from onboard import signals
from onboard.config import OnboardConfig
from shared.arguments import floats
from shared.config import ConfigError, load_config
from shared.transport import add_transport_args, transport_from_args

log = logging.getLogger("syt.onboard")


def _add_world_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", help="bundled world name or world file (default: the config's, paper-lab)")
    parser.add_argument("--start", type=floats(3, "--start"), metavar="X,Y,HEADING_DEG",
                        help="override the world's robot start")
    parser.add_argument("--target", type=floats(4, "--target"), metavar="X,Y,Z,YAW_DEG",
                        help="override the world's target placement (bottom centre)")


def _load_world(args: argparse.Namespace, config: OnboardConfig):
    from onboard.sim.world import load_world

    world = load_world(args.world or config.sim.world, robot_radius_m=config.base.radius_m,
                       mount=config.camera.mount())  # a room too low for the head is named here, with its file
    if args.start is not None:
        x, y, heading = args.start
        world = world.with_start(x, y, math.radians(heading))
    if args.target is not None:
        world = world.with_target(*args.target)
    return world


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="syt-onboard", description="The onboard agent of a syt robot.",
                                     epilog="usage, with the other commands:\n" + __doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path, metavar="FILE.toml", help="onboard configuration")
    parser.add_argument("--backend", choices=("sim", "hardware"),
                        help="device backend (default: the config's, sim); hardware reads [hardware.*]")
    parser.add_argument("--realtime", action="store_true", help="simulator: pace the clock like the real robot")
    parser.add_argument("--seed", type=int, help="simulator: odometry-noise seed")
    parser.add_argument("-v", "--verbose", action="store_true")
    _add_world_args(parser)
    add_transport_args(parser)
    return parser


def _overrides(args: argparse.Namespace) -> dict:
    pairs = {"backend": args.backend, "sim.world": args.world,
             "sim.realtime": True if args.realtime else None, "sim.seed": args.seed}
    return {k: v for k, v in pairs.items() if v is not None}


def run_agent(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    _setup_logging(args.verbose)
    from shared.world import WorldError

    try:
        config = load_config(OnboardConfig, args.config, _overrides(args))
        transport = transport_from_args(args)
        zenoh_config = transport.zenoh()  # a bad --zenoh-config is named before any device opens
        world = _load_world(args, config)
    except (ConfigError, WorldError, ValueError, OSError, zenoh.ZError) as exc:
        log.error("%s", exc)
        return 2
    from onboard.agent import Agent
    from onboard.backends import build_robot
    from onboard.devices import DeviceFault
    from onboard.hardware.stereo_rig import CalibrationFileError

    try:
        robot = build_robot(config, world)
    except (DeviceFault, CalibrationFileError, WorldError) as exc:
        log.error("cannot start the %s backend: %s", config.backend, exc)
        return 1
    stop = signals.stop_on_signals()
    from onboard.secure_transport import warn_if_exposed
    from onboard.zenoh_log import route_zenoh_log

    route_zenoh_log()  # refused TLS peers and access-control drops: only Zenoh sees them
    warn_if_exposed(zenoh_config)
    try:
        session = transport.open(zenoh_config)  # the config warn_if_exposed judged
    except Exception as exc:  # zenoh.ZError: the agent would have closed the devices; it never ran
        robot.devices.close()
        log.error("cannot open the Zenoh session: %s", exc)
        return 1
    try:
        agent = Agent(config, robot.devices, session, transport.robot_id, sim=robot.sim)
        agent.run(stop)
    finally:
        session.close()
    return 0


def run_render(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="syt-onboard render", description="Render a world's stereo view.")
    _add_world_args(parser)
    parser.add_argument("--config", type=Path, metavar="FILE.toml")
    parser.add_argument("--pan", type=float, default=0.0, metavar="DEG")
    parser.add_argument("--tilt", type=float, default=0.0, metavar="DEG")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR")
    args = parser.parse_args(argv)
    _setup_logging(False)
    from onboard.sim.preview import write_preview
    from shared.world import WorldError

    try:
        config = load_config(OnboardConfig, args.config)
        world = _load_world(args, config)
        problem = config.pantilt.check(args.pan, args.tilt)
        if problem:
            raise ValueError(problem)
    except (ConfigError, WorldError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    paths = write_preview(world, world.start, math.radians(args.pan), math.radians(args.tilt), args.out,
                          config.camera.intrinsics(), config.camera.mount())
    for path in paths:
        sys.stdout.write(f"{path}\n")
    return 0


def run_bench(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="syt-onboard bench", description="Measure the onboard side.")
    parser.add_argument("--json", action="store_true", help="print one JSON object (the only output form)")
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--backend", choices=("sim", "hardware"), default="sim",
                        help="sim: render and round trips; hardware: the Pioneer driver's latencies (over the emulator)")
    parser.add_argument("--port", help="hardware: a real Pioneer's port or URL instead of the emulator")
    args = parser.parse_args(argv)
    _setup_logging(False)
    from onboard.bench import run, run_hardware

    if args.backend == "hardware":
        try:
            sys.stdout.write(run_hardware(args.port) + "\n")
        except RuntimeError as exc:  # DeviceFault: nothing answers on the port
            log.error("%s", exc)
            return 1
        return 0
    sys.stdout.write(run(args.repeats) + "\n")
    return 0


def run_picture(argv: list[str]) -> int:
    """Export a built-in picture (the default target's, for instance) for the planner's target model."""
    parser = argparse.ArgumentParser(prog="syt-onboard picture", description="Write a built-in picture as PNG.")
    parser.add_argument("name", help="a built-in picture name, e.g. target")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE.png")
    args = parser.parse_args(argv)
    _setup_logging(False)
    from onboard.sim.textures import PictureError, load_picture
    from shared.image_files import write_rgb

    try:
        picture = load_picture(args.name)
    except PictureError as exc:
        log.error("%s", exc)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    try:
        write_rgb(args.out, picture)
    except OSError as exc:  # an extension OpenCV cannot write, a full disk
        log.error("%s", exc)
        return 1
    sys.stdout.write(f"{args.out}\n")
    return 0


def run_worlds(argv: list[str]) -> int:
    """``worlds generate``: furnished rooms, each checked to be searchable before it is written;
    ``worlds views``: rendered pairs with true depth of worlds, to score stereo on;
    ``worlds check``: can the simulator run these worlds with this robot (exit 2 naming each that cannot)."""
    from shared.world import suite_names

    suites = ", ".join(suite_names())
    parser = argparse.ArgumentParser(prog="syt-onboard worlds", description="World files.")
    commands = parser.add_subparsers(dest="command", required=True)
    generate = commands.add_parser("generate", help="write N generated rooms DIR/room-S-K.toml (same seed, same files)")
    generate.add_argument("--count", type=int, required=True, metavar="N")
    generate.add_argument("--seed", type=int, required=True, metavar="S")
    generate.add_argument("--out", type=Path, required=True, metavar="DIR")
    generate.add_argument("--max-turn-deg", type=float, metavar="D",
                          help="turn half the targets by up to D degrees from square to their support's edge, "
                               "0 to 45 (default: 10, as the shipped suites; the planner's facing sectors meet "
                               "at 22.5)")
    views = commands.add_parser("views", help="render stereo pairs with true depth of worlds, to score stereo on")
    views.add_argument("--worlds", required=True, metavar="NAMES",
                       help=f"comma-separated suites ({suites}), bundled names, world files or folders of them")
    views.add_argument("--per-world", type=int, default=25, metavar="N", help="views per world (default: 25)")
    views.add_argument("--seed", type=int, default=0, metavar="S", help="default: 0")
    views.add_argument("--out", type=Path, required=True, metavar="DIR")
    check = commands.add_parser("check", help="check worlds as the simulator loads them: the format, textures and "
                                              "pictures, and the robot fits")
    check.add_argument("worlds", nargs="+", metavar="WORLD",
                       help=f"suites ({suites}), bundled names, world files or folders of them")
    check.add_argument("--config", type=Path, metavar="FILE.toml", help="onboard configuration: the robot's size")
    args = parser.parse_args(argv)
    _setup_logging(False)
    if args.command == "check":
        return _check_worlds(args)
    if args.command == "views":
        if args.per_world < 1:
            parser.error(f"--per-world: must be at least 1, got {args.per_world}")
        return _write_views(args)
    if args.count < 1:
        parser.error(f"--count: must be at least 1, got {args.count}")
    if args.seed < 0:  # numpy's generators take no negative seed
        parser.error(f"--seed: must be 0 or more, got {args.seed}")
    if args.out.exists() and not args.out.is_dir():
        parser.error(f"--out must be a folder: {args.out} is a file")
    from onboard.sim.world_generator import MAX_TURN_DEG, TURN_LIMIT_DEG, write_worlds

    turn = MAX_TURN_DEG if args.max_turn_deg is None else args.max_turn_deg
    if not 0.0 <= turn <= TURN_LIMIT_DEG:  # the generator's own bound, refused by the flag's name
        parser.error(f"--max-turn-deg: must be from 0 to {TURN_LIMIT_DEG:g}, got {turn:g}")
    try:
        paths = write_worlds(args.count, args.seed, args.out, max_turn_deg=turn)
    except ValueError as exc:  # a folder holding other world files
        log.error("%s", exc)
        return 2
    except (OSError, RuntimeError) as exc:
        log.error("%s", exc)
        return 1
    for path in paths:
        sys.stdout.write(f"{path}\n")
    return 0


def _check_worlds(args: argparse.Namespace) -> int:
    from onboard.sim.world import load_world
    from shared.world import WorldError, expand_suites

    try:
        config = load_config(OnboardConfig, args.config)
        paths = expand_suites(args.worlds)
    except (ConfigError, WorldError) as exc:
        log.error("%s", exc)
        return 2
    failed = 0
    for path in paths:
        try:
            load_world(path, robot_radius_m=config.base.radius_m, mount=config.camera.mount())
        except WorldError as exc:
            log.error("%s", exc)
            failed += 1
    if not failed:
        sys.stdout.write(f"{len(paths)} worlds ok\n")
    return 2 if failed else 0


def _write_views(args: argparse.Namespace) -> int:
    from onboard.sim.stereo_views import write_views
    from shared.world import expand_suites

    try:
        index = write_views(list(expand_suites(args.worlds.split(","))), args.per_world, args.seed, args.out)
    except (OSError, ValueError) as exc:  # WorldError is a ValueError
        log.error("%s", exc)
        return 2
    sys.stdout.write(f"{index}\n")
    return 0


def run_emulate(argv: list[str]) -> int:
    """Both emulators on pseudo-terminals over one simulated world, until SIGINT or SIGTERM."""
    parser = argparse.ArgumentParser(
        prog="syt-onboard emulate", description="Emulate a Pioneer and a PTU-D46 on pseudo-terminals; print "
        'their paths and the truth link as one JSON line {"base", "pantilt", "truth"}.')
    _add_world_args(parser)
    parser.add_argument("--config", type=Path, metavar="FILE.toml", help="limits, odometry noise and seed")
    parser.add_argument("--seed", type=int, help="odometry-noise seed")
    args = parser.parse_args(argv)
    _setup_logging(False)
    from onboard.emulators.robot import EmulatedRobot
    from shared.world import WorldError

    try:
        config = load_config(OnboardConfig, args.config, {"sim.seed": args.seed} if args.seed is not None else {})
        world = _load_world(args, config)
    except (ConfigError, WorldError) as exc:
        log.error("%s", exc)
        return 2
    stop = signals.stop_on_signals()
    with EmulatedRobot(config, world, args.world or config.sim.world) as robot:
        sys.stdout.write(json.dumps(robot.ports()) + "\n")
        sys.stdout.flush()
        signals.wait(stop)
    return 0


def run_make_certs(argv: list[str]) -> int:
    _setup_logging(False)
    from onboard.make_certs import run

    return run(argv)


def run_calibrate_stereo(argv: list[str]) -> int:
    """Calibrate a stereo camera from chessboard pictures; print the RMS and what was used."""
    parser = argparse.ArgumentParser(prog="syt-onboard calibrate-stereo",
                                     description="Calibrate a stereo camera from chessboard pictures.")
    parser.add_argument("--images", type=Path, required=True, metavar="DIR",
                        help="left_*.png + right_*.png pairs, or side-by-side frames")
    parser.add_argument("--board", required=True, metavar="COLSxROWS", help="inner corners, e.g. 9x6")
    parser.add_argument("--square-mm", type=float, required=True, metavar="S", help="a square's side")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE.yaml")
    parser.add_argument("--max-rms-px", type=float, default=1.0, help="refuse a calibration worse than this")
    parser.add_argument("--swap-halves", action="store_true",
                        help="side-by-side frames hold the right image in their left half ([hardware.camera] "
                             "swap_halves must say so too)")
    args = parser.parse_args(argv)
    _setup_logging(False)
    from onboard.hardware.stereo_calibration import CalibrationError, calibrate_stereo

    try:
        summary = calibrate_stereo(args.images, args.board, args.square_mm, args.out, max_rms_px=args.max_rms_px,
                                   swap_halves=args.swap_halves)
    except CalibrationError as exc:
        log.error("calibrate-stereo: %s", exc)
        return 2
    sys.stdout.write(json.dumps(summary) + "\n")
    return 0


def run_probe(argv: list[str]) -> int:
    """List serial ports and cameras and what answers on them, or identify one port."""
    parser = argparse.ArgumentParser(prog="syt-onboard probe", description="Find the robot's devices.")
    parser.add_argument("--port", metavar="PORT", help="identify only this serial port (a path or a URL)")
    parser.add_argument("--baud", type=int, default=9600)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.port is not None and not args.port.strip():  # an empty variable in a script: not "every port"
        parser.error("--port: empty; give a serial port's path or URL, or leave --port out to probe every port")
    _setup_logging(False)
    from onboard.probe import describe, identify_port, probe_all

    if args.port is not None:
        answer = identify_port(args.port, args.baud)
        sys.stdout.write((json.dumps(answer) if args.json else describe(answer)) + "\n")
        return 0 if answer["device"] != "unknown" else 1
    found = probe_all()
    if args.json:
        sys.stdout.write(json.dumps(found) + "\n")
        return 0
    for entry in found["serial"]:
        usb = entry["usb"]
        ids = f" (USB {usb['vendor']}:{usb['product']} serial {usb['serial']})" if usb else ""
        sys.stdout.write(f"{describe(entry['answer'])}{ids}\n")
    for camera in found["cameras"]:
        sys.stdout.write(describe(camera) + "\n")
    if not found["serial"] and not found["cameras"]:
        sys.stdout.write("no serial ports and no cameras found\n")
    return 0


def run_compile(argv: list[str]) -> int:
    """The simulator's renderer into numba's on-disk cache, as an agent starting compiles it: ``make``
    runs this once after installing, or each agent of a fresh checkout compiles it (about 25 s)."""
    argparse.ArgumentParser(prog="syt-onboard compile",
                            description="Compile the simulator's renderer into numba's cache.").parse_args(argv)
    _setup_logging(False)
    from onboard.sim.robot import build_sim_robot
    from onboard.sim.world import load_world

    config = OnboardConfig()
    build_sim_robot(config, load_world(config.sim.world, robot_radius_m=config.base.radius_m))
    return 0


_COMMANDS = {"render": run_render, "bench": run_bench, "picture": run_picture, "worlds": run_worlds,
             "emulate": run_emulate, "calibrate-stereo": run_calibrate_stereo, "probe": run_probe,
             "make-certs": run_make_certs, "compile": run_compile}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in _COMMANDS:
        return _COMMANDS[argv[0]](argv[1:])
    return run_agent(argv)


def _setup_logging(verbose: bool) -> None:
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")


if __name__ == "__main__":
    sys.exit(main())
