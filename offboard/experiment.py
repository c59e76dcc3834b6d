"""``syt-offboard experiment``: a grid of full searches, each against its own simulated robot (report §5.2).

The grid is worlds × robot starts × target placements × cost functions × priors × seeds × methods
(``syt`` and the baselines of :mod:`offboard.baselines`, which ignore the cost function and so run
once per start × target × prior). ``--preset paper`` is the report's 160 runs on ``paper-lab``.

Each run is its own worker process (``python -m offboard.experiment SPEC.json``) that starts its own
onboard agent on a fresh loopback port and runs :func:`offboard.search_run.run_search`; ``--jobs``
workers run at once. Every finished run appends a row to ``results.csv`` at once, so an interrupted
sweep resumes where it stopped (rows are keyed by the run; failed runs are tried again).

The harness is the experimenter: it reads the world file (:mod:`offboard.experiment_world`; offboard
code never imports the simulator) to place the robot and the target, to write the ``tables`` prior,
and to measure the estimate's error and SPL's shortest path. The planner sees none of it. Success is
"found, and the estimate within :data:`SUCCESS_RADIUS_M` of the true centre".
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import logging
import math
import os
import signal
import subprocess
import sys
import threading
import time
import tomllib
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from offboard.baselines import BASELINES, BaselineContext
from offboard.experiment_report import append_row, finished_keys, write_report
from offboard.experiment_world import (Placement, Start, WorldFacts, load_facts, robot_starts, tables_hints,
                                       target_placements, viewpoint)
from shared.arguments import floats

log = logging.getLogger(__name__)

SUCCESS_RADIUS_M = 0.5  # a "found" whose estimate is farther from the truth is a false detection


# --- the grid --------------------------------------------------------------------------------------

def _fmt(values: tuple[float, ...]) -> str:
    return ",".join(f"{v:g}" for v in values)


@dataclass(frozen=True)
class Run:
    method: str  # "syt" or a baseline's name
    world: str
    start: Start
    target: Placement
    cost: int | None  # None for baselines (the cost function is SYT's)
    prior: str  # "uniform" or "tables"
    seed: int

    def fields(self) -> dict[str, str]:
        return {"method": self.method, "world": self.world, "start": _fmt(self.start), "target": _fmt(self.target),
                "cost": "" if self.cost is None else str(self.cost), "prior": self.prior, "seed": str(self.seed)}

    @property
    def key(self) -> str:
        return "|".join(self.fields().values())

    @property
    def slug(self) -> str:
        tag = hashlib.sha1(self.key.encode()).hexdigest()[:10]
        return f"{self.method}-{self.cost or 'x'}-{self.prior}-{self.seed}-{tag}"


@dataclass(frozen=True)
class GridSpec:
    worlds: tuple[str, ...] = ("paper-lab",)
    starts: int = 5
    targets: int = 4
    costs: tuple[int, ...] = (1, 2, 3, 4)
    priors: tuple[str, ...] = ("uniform", "tables")
    seeds: tuple[int, ...] = (0,)
    methods: tuple[str, ...] = ("syt",)
    start_overrides: tuple[Start, ...] = ()  # replace the derived starts (every world)
    target_overrides: tuple[Placement, ...] = ()


PAPER = GridSpec()
BASELINE_METHODS = tuple(BASELINES)


def build_runs(spec: GridSpec) -> list[Run]:
    """The grid in a fixed order (``--limit`` takes its head): per world, seed, start, target, prior, method."""
    runs = []
    for name in spec.worlds:
        world = load_facts(name)
        starts = list(spec.start_overrides) or robot_starts(world, spec.starts)
        targets = list(spec.target_overrides) or target_placements(world, spec.targets)
        for seed, start, target, prior, method in itertools.product(spec.seeds, starts, targets, spec.priors,
                                                                     spec.methods):
            costs = spec.costs if method == "syt" else (None,)  # the cost function is SYT's alone
            runs += [Run(method, name, start, target, c, prior, seed) for c in costs]
    return runs


# --- results.csv rows ------------------------------------------------------------------------------

def make_row(run: Run, world: WorldFacts, summary: dict | None, run_wall_s: float, error: str = "") -> dict:
    """A results.csv row: the run, its summary (``None`` if it crashed), the estimate's error, SPL."""
    truth = world.truth(run.target)
    _, shortest = viewpoint(truth, run.start[:2])
    row = {**run.fields(), "key": run.key, "run_wall_s": round(run_wall_s, 2),
           "shortest_path_m": round(shortest, 3) if math.isfinite(shortest) else ""}
    if summary is None:
        return {**row, "found": False, "status": f"error: {error}"[:300], "success": False, "spl": 0.0, "error": error}
    row.update({k: v for k, v in summary.items() if k != "prior"}, prior_spec=summary.get("prior", ""))
    row["target_estimate_m"] = json.dumps(summary.get("target_estimate_m"))
    estimate = summary.get("target_estimate_m")
    err = float(np.linalg.norm(np.array(estimate) - truth.target_center_m)) if summary["found"] and estimate else None
    success = err is not None and err <= SUCCESS_RADIUS_M
    longest = max(float(summary["distance_m"]), shortest) if math.isfinite(shortest) else 0.0
    spl = (shortest / longest if longest > 0 else 1.0) if success and math.isfinite(shortest) else 0.0
    return {**row, "estimate_error_m": "" if err is None else round(err, 3), "success": success, "spl": round(spl, 4)}


# --- one run (in its own worker process) -----------------------------------------------------------

@dataclass(frozen=True)
class WorkerSpec:
    run: dict  # Run as a dict
    world_path: str
    picture: str
    prior_spec: str
    budget_s: float
    out_dir: str


def run_one(spec: WorkerSpec) -> dict:
    """Start the run's agent, search, stop the agent; the summary is also in ``out_dir/summary.json``."""
    from offboard.search_run import SearchRequest, run_search
    from shared.launch import onboard_agent
    from shared.transport import TransportConfig

    run = Run(**{**spec.run, "start": tuple(spec.run["start"]), "target": tuple(spec.run["target"])})
    world = load_facts(spec.world_path)
    out = Path(spec.out_dir)
    agent_args = ["--backend", "sim", "--world", spec.world_path, "--start", _fmt(run.start),
                  "--target", _fmt(run.target), "--seed", str(run.seed)]
    policy = None
    if run.method != "syt":
        policy = BASELINES[run.method](BaselineContext(seed=run.seed, truth=world.truth(run.target)))
    with onboard_agent(agent_args, out / "onboard.log") as agent:
        transport = TransportConfig(robot_id="syt", connect=(agent.endpoint,), multicast_scouting=False)
        with transport.open() as session:
            agent.wait_ready(session, "syt")
        request = SearchRequest(pictures=(Path(spec.picture),), target_size_m=world.target_size_m, room_m=world.room_m,
                                cost=run.cost or 3, priors=(spec.prior_spec,), budget_s=spec.budget_s, out_dir=out,
                                record=False)
        return run_search(transport, request, policy)


def _worker_main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger().handlers[0].setLevel(logging.WARNING)  # search.log keeps the details
    run_one(WorkerSpec(**json.loads(Path(argv[0]).read_text())))
    return 0


# --- the sweep -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SweepSettings:
    out: Path
    jobs: int = field(default_factory=lambda: os.cpu_count() or 1)
    budget_s: float = 1800.0
    run_timeout_s: float = 3600.0  # wall clock, per run


@dataclass
class Progress:
    total: int
    skipped: int
    done: int = 0
    failed: int = 0
    started: float = field(default_factory=time.monotonic)

    def eta_s(self) -> float:
        finished = self.done + self.failed
        left = self.total - self.skipped - finished
        return math.inf if finished == 0 else (time.monotonic() - self.started) / finished * left


class _Workers:
    """Worker processes in their own process groups (each with its agent): stopped together on Ctrl-C."""

    def __init__(self, jobs: int):
        self.lock, self.running, self.stopping = threading.Lock(), set(), False
        # the runs share the cores: one numba thread per worker when there are as many workers as cores
        threads = str(max(1, (os.cpu_count() or 1) // max(jobs, 1)))
        self.env = {**os.environ, "NUMBA_NUM_THREADS": threads, "OMP_NUM_THREADS": threads}

    def run(self, cmd: list[str], log_path: Path, timeout_s: float) -> int | None:
        with log_path.open("w") as log_file, self.lock:
            if self.stopping:
                return None
            proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT, start_new_session=True,
                                    env=self.env)
            self.running.add(proc)
        try:
            return proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            return -1
        finally:
            with self.lock:
                self.running.discard(proc)

    def stop(self) -> None:
        with self.lock:
            self.stopping = True
            for proc in self.running:
                os.killpg(proc.pid, signal.SIGTERM)  # the worker and its agent (which stops its base on SIGTERM)


def _prepare(runs: list[Run], out: Path) -> dict[str, tuple[WorldFacts, Path, Path]]:
    """Per world: its facts, the target's picture for the planner, the tables hints file."""
    prepared = {}
    for name in sorted({r.world for r in runs}):
        world = load_facts(name)
        pictures, hints = out / "pictures", out / "priors"
        pictures.mkdir(parents=True, exist_ok=True)
        hints.mkdir(parents=True, exist_ok=True)
        picture = world.path.parent / world.target_picture
        if not picture.is_file():
            picture = pictures / f"{world.name}.png"
            subprocess.run([sys.executable, "-m", "onboard.cli", "picture", Path(world.target_picture).stem,
                            "--out", str(picture)], check=True, capture_output=True)
        hint_file = hints / f"{world.name}-tables.toml"
        if world.tables():
            hint_file.write_text(tables_hints(world))
        prepared[name] = (world, picture, hint_file)
    return prepared


def _execute(run: Run, prepared: dict, settings: SweepSettings, workers: _Workers) -> dict | None:
    world, picture, hint_file = prepared[run.world]
    run_dir = settings.out / "runs" / run.slug
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "summary.json").unlink(missing_ok=True)  # a leftover of an interrupted attempt
    prior = "uniform" if run.prior == "uniform" else f"hints:{hint_file}"
    spec = WorkerSpec(asdict(run), str(world.path), str(picture), prior, settings.budget_s, str(run_dir))
    (run_dir / "spec.json").write_text(json.dumps(asdict(spec), indent=2))
    started = time.monotonic()
    rc = workers.run([sys.executable, "-m", "offboard.experiment", str(run_dir / "spec.json")],
                     run_dir / "worker.log", settings.run_timeout_s)
    wall = time.monotonic() - started
    if rc is None or workers.stopping:
        return None  # interrupted: not a result, redone on resume
    if rc == 0 and (run_dir / "summary.json").is_file():
        return make_row(run, world, json.loads((run_dir / "summary.json").read_text()), wall)
    tail = (run_dir / "worker.log").read_text().strip().splitlines()[-1:] or ["no output"]
    reason = "timeout" if rc == -1 else f"exit {rc}: {tail[0]}"
    return make_row(run, world, None, wall, reason)


def sweep(runs: list[Run], settings: SweepSettings, on_progress: Callable[[Progress], None] | None = None) -> Progress:
    """Run what ``results.csv`` does not hold yet; each row is appended as its run finishes."""
    settings.out.mkdir(parents=True, exist_ok=True)
    results = settings.out / "results.csv"
    done = finished_keys(results)
    todo = [r for r in runs if r.key not in done]
    progress = Progress(total=len(runs), skipped=len(runs) - len(todo))
    prepared = _prepare(todo, settings.out)
    workers = _Workers(settings.jobs)
    if on_progress:
        on_progress(progress)
    with ThreadPoolExecutor(max_workers=max(1, settings.jobs)) as pool:
        futures = [pool.submit(_execute, r, prepared, settings, workers) for r in todo]
        try:
            for future in as_completed(futures):
                row = future.result()
                if row is None:
                    continue
                append_row(results, row)
                progress.failed += row["status"].startswith("error")
                progress.done += not row["status"].startswith("error")
                if on_progress:
                    on_progress(progress)
        except BaseException:
            workers.stop()
            pool.shutdown(cancel_futures=True)
            raise
    return progress


# --- the command line ------------------------------------------------------------------------------

PRESETS = {"paper": PAPER}
PRIORS = ("uniform", "tables")


def _list(kind: type, allowed: tuple | None = None):
    def parse(text: str) -> tuple:
        try:
            values = tuple(kind(v) for v in text.split(",") if v)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list, got {text!r}") from None
        bad = [v for v in values if allowed is not None and v not in allowed]
        if bad or not values:
            raise argparse.ArgumentTypeError(f"{text!r}: choose from {', '.join(map(str, allowed or ()))}")
        return values
    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("experiment-out"), metavar="DIR",
                        help="results.csv, report.md, plots and one folder per run; a rerun resumes")
    parser.add_argument("--preset", choices=sorted(PRESETS), default="paper",
                        help="the grid to start from (paper: the report's 160 runs); the options below override it")
    parser.add_argument("--baselines", action="store_true", help="add every baseline to the methods")
    parser.add_argument("--worlds", type=_list(str), metavar="W,..", help="bundled world names or world files")
    parser.add_argument("--costs", type=_list(int, (1, 2, 3, 4)), metavar="C,..")
    parser.add_argument("--priors", type=_list(str, PRIORS), metavar="P,..", help="uniform, tables")
    parser.add_argument("--seeds", type=_list(int), metavar="S,..", help="simulator seeds (and the random baseline's)")
    parser.add_argument("--methods", type=_list(str, ("syt", *BASELINE_METHODS)), metavar="M,..",
                        help=f"syt, {', '.join(BASELINE_METHODS)}")
    parser.add_argument("--starts", type=int, metavar="N", help="robot starts per world (derived from the world)")
    parser.add_argument("--targets", type=int, metavar="N", help="target placements per world (on its tables)")
    parser.add_argument("--start", type=floats(3, "--start"), action="append", metavar="X,Y,HEADING_DEG",
                        help="use these robot starts instead (repeatable)")
    parser.add_argument("--target", type=floats(4, "--target"), action="append", metavar="X,Y,Z,YAW_DEG",
                        help="use these target placements instead (repeatable)")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, metavar="N", help="runs at once")
    parser.add_argument("--budget-s", type=float, default=1800.0, metavar="SECONDS", help="robot-time budget K")
    parser.add_argument("--limit", type=int, metavar="N", help="only the first N runs of the grid")
    parser.add_argument("--run-timeout-s", type=float, default=3600.0, metavar="SECONDS", help="wall clock per run")
    parser.add_argument("--report-only", action="store_true", help="rewrite report.md and the plots from results.csv")


def grid_from_args(args: argparse.Namespace) -> GridSpec:
    spec = PRESETS[args.preset]
    given = {"worlds": args.worlds, "costs": args.costs, "priors": args.priors, "seeds": args.seeds,
             "methods": args.methods, "starts": args.starts, "targets": args.targets,
             "start_overrides": tuple(args.start or ()), "target_overrides": tuple(args.target or ())}
    spec = replace(spec, **{k: v for k, v in given.items() if v})
    if args.baselines:
        spec = replace(spec, methods=tuple(dict.fromkeys(spec.methods + BASELINE_METHODS)))
    return spec


def _show(progress: Progress) -> None:
    finished = progress.skipped + progress.done + progress.failed
    filled = int(30 * finished / max(progress.total, 1))
    eta = progress.eta_s()
    eta_text = "?" if not math.isfinite(eta) else f"{int(eta // 3600)}h{int(eta % 3600 // 60):02d}m{int(eta % 60):02d}s"
    sys.stderr.write(f"\r[{'#' * filled}{'-' * (30 - filled)}] {finished}/{progress.total} runs "
                     f"({progress.skipped} already done), {progress.failed} failed, ETA {eta_text}   ")
    sys.stderr.flush()


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(args: argparse.Namespace) -> int:
    failed = 0
    if not args.report_only:
        try:
            runs = build_runs(grid_from_args(args))
        except (ValueError, OSError, KeyError, tomllib.TOMLDecodeError) as exc:
            log.error("cannot build the grid: %s", exc)
            return 2
        runs = runs[:args.limit] if args.limit else runs
        log.info("%d runs into %s, %d at a time", len(runs), args.out, args.jobs)
        started = time.monotonic()
        signal.signal(signal.SIGTERM, _interrupt)  # stop the workers and their agents, as on Ctrl-C
        try:
            progress = sweep(runs, SweepSettings(args.out, args.jobs, args.budget_s, args.run_timeout_s), _show)
        except KeyboardInterrupt:
            sys.stderr.write("\ninterrupted: run the same command again to resume\n")
            return 130
        sys.stderr.write("\n")
        failed = progress.failed
        log.info("%d runs done, %d failed, %d already done, in %.0f s", progress.done, failed, progress.skipped,
                 time.monotonic() - started)
    if not (args.out / "results.csv").is_file():
        log.error("no results in %s: nothing to report", args.out)
        return 2
    for path in write_report(args.out / "results.csv", args.out):
        log.info("wrote %s", path)
    return 0 if failed == 0 else 1


if __name__ == "__main__":  # a worker: python -m offboard.experiment SPEC.json
    sys.exit(_worker_main(sys.argv[1:]))
