"""``syt-offboard experiment``: a grid of full searches, each against its own simulated robot (report §5.2).

The grid is worlds × robot starts × target placements × cost functions × priors × seeds × methods
(``syt`` and the baselines of :mod:`offboard.experiments.baselines`, which ignore the cost function and so run
once per start × target × prior). ``--preset paper`` is the report's 160 runs on ``paper-lab``.

``--jobs`` worker processes (``python -m offboard.experiments.harness --serve``) run at once, each with its own
onboard agent on its own loopback port. A worker takes run after run: it resets its simulated robot
for the run (``sim/reset``: the run's start, target placement and noise seed, so a run gives the same
numbers whichever worker runs it, in whatever order) and runs :func:`offboard.search.run.run_search`
with a fresh planner; a run that fails gets the worker a fresh agent. Every finished run appends a
row to ``results.csv`` at once, so an interrupted sweep resumes where it stopped (rows are keyed by
the run; failed runs are tried again; ``sweep.json`` holds the settings they ran with, and a sweep with
other settings, or with other bytes of a world, its picture or a detectability table, is refused that
folder). Logs: ``runs/<run>/search.log`` per run, ``workers/worker-<k>/{worker,onboard}.log`` per worker.

The harness is the experimenter: it reads the world file (:mod:`offboard.experiments.world_facts`; offboard
code never imports the simulator) to place the robot and the target, to write the ``tables`` prior,
and to measure the estimate's error and SPL's shortest path. The planner sees none of it. Success is
"found, and the estimate within :data:`SUCCESS_RADIUS_M` of the true centre".
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import hashlib
import itertools
import json
import logging
import math
import os
import queue
import select
import signal
import subprocess
import sys
import threading
import time
import tomllib
from importlib import resources
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from offboard.experiments.baselines import BASELINES, BaselineContext
from offboard.experiments.calibration import LOOKS_FILE
from offboard.experiments.report import COLUMNS, append_row, finished_keys, load_results, write_report
from offboard.experiments.world_facts import (Placement, Start, WorldFacts, load_facts, robot_starts, simulator_refuses,
                                              tables_hints, target_placements, viewpoint)
from offboard.search.loop import Search, SearchConfig
from shared.arguments import floats, number, probability
from shared.config import load_config
from shared.world import expand_suites, resolve_world, suite_names

if TYPE_CHECKING:
    from offboard.robot.robot_client import RobotClient

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
    prior: str  # one of PRIORS
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
    # one run a key: a world, start, seed or value given twice (a suite and one of its rooms, say)
    # would be done twice into one folder
    unique: dict[str, Run] = {}
    for run in runs:
        unique.setdefault(run.key, run)
    return list(unique.values())


# --- results.csv rows ------------------------------------------------------------------------------

def make_row(run: Run, world: WorldFacts, summary: dict | None, run_wall_s: float, error: str = "") -> dict:
    """A results.csv row: the run, its summary (``None`` if it crashed), the estimate's error, SPL."""
    truth = world.truth(run.target)
    _, shortest = viewpoint(truth, run.start[:2])
    row = {**run.fields(), "key": run.key, "run_wall_s": round(run_wall_s, 2), "run_dir": f"runs/{run.slug}",
           "shortest_path_m": round(shortest, 3) if math.isfinite(shortest) else ""}
    if summary is None:
        return {**row, "found": False, "status": f"error: {error}"[:300], "success": False, "spl": 0.0, "error": error}
    row.update({k: v for k, v in summary.items() if k != "prior"}, prior_spec=summary.get("prior", ""))
    row["target_estimate_m"] = json.dumps(summary.get("target_estimate_m"))
    estimate = summary.get("target_estimate_m")
    err = float(np.linalg.norm(np.array(estimate) - truth.target_center_m)) if summary["found"] and estimate else None
    success = err is not None and err <= SUCCESS_RADIUS_M
    return {**row, "estimate_error_m": "" if err is None else round(err, 3), "success": success,
            "spl": spl(success, shortest, float(summary["distance_m"]))}


def spl(success: bool, shortest_m: float, distance_m: float) -> float:
    """Success weighted by path length: S·ℓ/max(p, ℓ), ℓ the shortest path, p the distance driven (0
    where ``shortest_m`` is inf: no position the robot can reach sees the target)."""
    if not success or not math.isfinite(shortest_m):
        return 0.0
    longest = max(distance_m, shortest_m)
    return round(shortest_m / longest if longest > 0 else 1.0, 4)


def rescore(out: Path) -> int:
    """Make each row of ``out/results.csv`` again with this code's yardstick: its shortest path (from
    its run's ``spec.json``: the world, start and target) and SPL; nothing the run measured
    changes. For rows made before the yardstick changed, so that they can be read beside new ones.
    Returns the rows whose SPL changed; the file is replaced whole, or not at all."""
    results = out / "results.csv"
    load_results(results, latest=False)  # refuse a malformed file before touching it, naming the line
    with results.open(newline="") as f:
        rows = list(csv.DictReader(f))
    worlds: dict[str, WorldFacts] = {}
    changed = 0
    for line, row in enumerate(rows, start=2):
        spec_file = out / row["run_dir"] / "spec.json"
        try:
            spec = json.loads(spec_file.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"{results}:{line}: its run's {spec_file} cannot be read ({exc})") from None
        name = spec["run"]["world"]  # a bundled name or a path, as the sweep was given it
        if name not in worlds:
            worlds[name] = load_facts(name)
        world = worlds[name]
        _, shortest = viewpoint(world.truth(tuple(spec["run"]["target"])), tuple(spec["run"]["start"][:2]))
        score = spl(row["success"] == "True", shortest, float(row["distance_m"] or 0.0))
        changed += score != float(row["spl"])
        row.update(shortest_path_m=round(shortest, 3) if math.isfinite(shortest) else "", spl=score)
    written = results.with_name(results.name + ".new")
    with written.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
        f.flush()
        os.fsync(f.fileno())
    written.replace(results)
    return changed


# --- the workers: long-lived processes, each with its own simulated robot -------------------------

@dataclass(frozen=True)
class WorkerSpec:
    run: dict  # Run as a dict
    world_path: str
    picture: str
    prior_spec: str
    budget_s: float | None
    out_dir: str
    move_threshold: float | None = None  # Θ_move; None: the planner's default
    config_path: str | None = None  # SearchConfig TOML for every run; None: the defaults


class _RunWorker:
    """The worker side (``python -m offboard.experiments.harness --serve``): one onboard agent, kept for run
    after run in the same world and reset between them (``sim/reset``: start, target placement and
    noise seed; the planner starts afresh each run), and the detectors, built once. That saves the
    agent's and the planner's start-up, several seconds a run."""

    def __init__(self, log_dir: Path):
        self._log_dir = log_dir
        self._agent_world: str | None = None
        self._agent_stack = contextlib.ExitStack()
        self._transport = None
        self._detectors: dict = {}

    def run(self, spec: WorkerSpec) -> dict:
        """Reset the robot for the run, search, write ``out_dir/summary.json``; the summary."""
        from offboard.robot.robot_client import RobotClient
        from offboard.search.run import SearchRequest, run_search

        run = Run(**{**spec.run, "start": tuple(spec.run["start"]), "target": tuple(spec.run["target"])})
        world = load_facts(spec.world_path)
        transport = self._agent(spec.world_path)
        with transport.open() as session, RobotClient(session, "syt") as robot:
            robot.sim_reset(run.start, run.target, run.seed)
        policy = None
        if run.method != "syt":
            policy = BASELINES[run.method](BaselineContext(seed=run.seed, truth=world.truth(run.target)))
        request = SearchRequest(pictures=(Path(spec.picture),), target_size_m=world.target_size_m,
                                target_sides=world.target_sides, room_m=world.room_m,
                                cost=run.cost or 3, priors=(spec.prior_spec,), budget_s=spec.budget_s,
                                move_threshold=spec.move_threshold,
                                config_path=None if spec.config_path is None else Path(spec.config_path),
                                out_dir=Path(spec.out_dir), record=False, checkpoint=False)  # a failed run is re-run
        return run_search(transport, request, policy, self._detectors, after_action=log_true_pose)

    def close(self) -> None:
        """Stop the agent; the next run (after a failed one: its state is not to be trusted) starts a fresh one."""
        self._agent_stack.close()
        self._agent_world = None

    def _agent(self, world_path: str):
        from shared.launch import onboard_agent
        from shared.transport import TransportConfig

        if self._agent_world != world_path:
            self.close()
            agent = self._agent_stack.enter_context(onboard_agent(["--backend", "sim", "--world", world_path],
                                                                  self._log_dir / "onboard.log"))
            self._transport = TransportConfig(robot_id="syt", connect=(agent.endpoint,), multicast_scouting=False)
            with self._transport.open() as session:
                agent.wait_ready(session, "syt")
            self._agent_world = world_path
        return self._transport


def log_true_pose(search: Search, robot: RobotClient) -> None:
    """Put the simulator's true pose beside the estimate in the newest look's log entry (``true_x_m``,
    ``true_y_m``, ``true_heading_deg``): the robot has not moved since that look, and the pair tells a
    localisation error from a stereo one. The experimenter's truth: written after the look, never
    read by the search."""
    looks = search.state.look_log
    if looks and looks[-1]["action"] == search.state.actions and "true_x_m" not in looks[-1]:
        pose = robot.sim_truth()
        looks[-1].update(true_x_m=round(pose.x_m, 3), true_y_m=round(pose.y_m, 3),
                         true_heading_deg=round(pose.heading_deg, 2))


def _serve(log_dir: Path) -> int:
    """The worker's loop: a spec path per line on stdin; per run, one line on stdout: ``ok`` or
    ``error: ...``. Ends at end of input."""
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger().handlers[0].setLevel(logging.WARNING)  # each run's search.log keeps the details
    with contextlib.closing(_RunWorker(log_dir)) as worker:
        for line in sys.stdin:
            try:
                worker.run(WorkerSpec(**json.loads(Path(line.strip()).read_text())))
                answer = "ok"
            except Exception as exc:  # the run failed, not the worker: report it, start the next afresh
                log.exception("run %s failed", line.strip())
                answer = f"error: {type(exc).__name__}: {exc}".replace("\n", " ")
                worker.close()
            sys.stdout.write(answer + "\n")
            sys.stdout.flush()
    return 0


# --- the sweep -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SweepSettings:
    out: Path
    jobs: int = field(default_factory=lambda: os.cpu_count() or 1)
    budget_s: float | None = None  # K for every run; None: the configuration's (1800 s by default)
    run_timeout_s: float = 3600.0  # wall clock, per run
    move_threshold: float | None = None  # Θ_move for every SYT run
    config_path: Path | None = None  # SearchConfig TOML for every run


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


class _WorkerProcess:
    """The sweep's handle on one worker process (in its own process group, with its agent)."""

    def __init__(self, log_dir: Path, env: dict):
        log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = log_dir / "worker.log"
        self._log = self.log_path.open("a")
        self.proc = subprocess.Popen([sys.executable, "-m", "offboard.experiments.harness", "--serve", str(log_dir)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log, text=True,
                                     start_new_session=True, env=env)

    def run(self, spec_path: Path, timeout_s: float) -> str:
        """``ok``, ``error: ...``, ``timeout`` or ``died: ...`` (then this worker is finished)."""
        try:
            self.proc.stdin.write(f"{spec_path}\n")
            self.proc.stdin.flush()
        except BrokenPipeError:
            return self._died()
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        if not ready:
            self.kill()
            return "timeout"
        answer = self.proc.stdout.readline().strip()
        return answer or self._died()

    def _died(self) -> str:
        self.proc.wait()
        tail = self.log_path.read_text().strip().splitlines()[-1:] or ["no output"]
        return f"died: exit {self.proc.returncode}: {tail[0]}"

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.alive:
            os.killpg(self.proc.pid, sig)
        self.proc.wait()

    def close(self) -> None:
        """End of input: the worker stops its agent and exits."""
        try:
            self.proc.stdin.close()
            self.proc.wait(timeout=30)
        except (subprocess.TimeoutExpired, BrokenPipeError):
            self.kill()
        self._log.close()


class _Workers:
    """``jobs`` long-lived worker processes, each lent to one run at a time; stopped together on Ctrl-C."""

    def __init__(self, jobs: int, log_dir: Path):
        self.lock, self.stopping = threading.Lock(), False
        # the runs share the cores: one numba thread per worker (and its agent) when there are as many
        # workers as cores; else one run's kernels take every core while another plans. OpenCV gets one
        # thread whatever --jobs: its results depend on its thread count (a run of hand/library took 49
        # looks with two, 39 with one), and a sweep's figures must not depend on --jobs
        threads = str(max(1, (os.cpu_count() or 1) // max(jobs, 1)))
        self.env = {**os.environ, "NUMBA_NUM_THREADS": threads, "OMP_NUM_THREADS": threads,
                    "OPENCV_FOR_THREADS_NUM": "1"}
        self.log_dir = log_dir
        self.idle: queue.Queue[int] = queue.Queue()
        for index in range(jobs):
            self.idle.put(index)
        self.processes: dict[int, _WorkerProcess] = {}

    def run(self, spec_path: Path, timeout_s: float) -> str | None:
        """The worker's answer for this run (see :meth:`_WorkerProcess.run`); None if the sweep stops."""
        index = self.idle.get()
        try:
            with self.lock:
                if self.stopping:
                    return None
                process = self.processes.get(index)
                if process is None or not process.alive:
                    process = self.processes[index] = _WorkerProcess(self.log_dir / f"worker-{index}", self.env)
            return process.run(spec_path, timeout_s)
        finally:
            self.idle.put(index)

    def close(self) -> None:
        for process in self.processes.values():
            process.close()

    def stop(self) -> None:
        with self.lock:
            self.stopping = True
            for process in self.processes.values():
                process.kill(signal.SIGTERM)  # the worker and its agent (which stops its base on SIGTERM)


class SweepRefused(ValueError):
    """A sweep that cannot start: a world the simulator cannot run, a prior a world cannot have."""


def _prepare(runs: list[Run], out: Path) -> dict[str, tuple[WorldFacts, Path, Path]]:
    """Per world: its facts, the target's picture for the planner, the tables hints file. Refuses
    (:class:`SweepRefused`) before any run starts what would fail every run of a world."""
    names = sorted({r.world for r in runs})
    if names:
        _check_worlds([str(resolve_world(n)) for n in names])
    prepared = {}
    for name in names:
        world = load_facts(name)
        hints = out / "priors"
        hints.mkdir(parents=True, exist_ok=True)
        picture = world.picture_file(out / "pictures")
        tag = hashlib.sha1(str(world.path.resolve()).encode()).hexdigest()[:8]  # two worlds may share a name
        hint_file = hints / f"{world.name}-{tag}-tables.toml"
        if any(r.world == name and r.prior == "tables" for r in runs):
            try:
                hint_file.write_text(tables_hints(world))
            except ValueError as exc:
                raise SweepRefused(f"prior tables: {exc}") from None
            if len(world.knowledge_surfaces()) == 1:
                log.warning("prior tables in %s: one surface holds all its mass, so it tells the planner where "
                            "the target is", world.name)
        prepared[name] = (world, picture, hint_file)
    for world, start, target in unscorable(runs, {n: facts for n, (facts, _, _) in prepared.items()}):
        log.warning("%s from (%s): no position the robot can drive to sees the target at (%s) by SPL's rule "
                    "(the detector's rate ≥ 0.8, the whole picture in plain view), so its runs score SPL 0 "
                    "however soon they find it", world, _fmt(start), _fmt(target))
    return prepared


def unscorable(runs: list[Run], worlds: dict[str, WorldFacts]) -> list[tuple[str, Start, Placement]]:
    """The scenarios (world, start, target) of ``runs`` whose SPL has no shortest path: said before the
    sweep, so that a room of one's own is not read from its SPL alone."""
    scenarios = sorted({(r.world, r.start, r.target) for r in runs})
    return [(name, start, target) for name, start, target in scenarios
            if not math.isfinite(viewpoint(worlds[name].truth(target), start[:2])[1])]


def _check_worlds(paths: list[str]) -> None:
    """The simulator's own check of the worlds (``syt-onboard worlds check``), in its process: this
    side never imports the simulator."""
    refused = simulator_refuses("worlds", "check", *paths)
    if refused:
        raise SweepRefused(f"the simulator cannot run {refused}")


# what a run writes into its folder (:func:`offboard.search.run.run_search`), removed before each attempt so
# that a run that fails this time leaves none of an earlier attempt's (its looks.jsonl would feed the
# calibration and coverage of an error row)
RUN_OUTPUTS = ("summary.json", LOOKS_FILE, "search.png", "search.log", "search.rrd")


def _execute(run: Run, prepared: dict, settings: SweepSettings, workers: _Workers) -> dict | None:
    world, picture, hint_file = prepared[run.world]
    run_dir = settings.out / "runs" / run.slug
    run_dir.mkdir(parents=True, exist_ok=True)
    for name in RUN_OUTPUTS:  # leftovers of an earlier attempt: a failed run must not be read with its looks
        (run_dir / name).unlink(missing_ok=True)
    prior = f"hints:{hint_file}" if run.prior == "tables" else run.prior  # the others are search --prior kinds
    spec = WorkerSpec(asdict(run), str(world.path), str(picture), prior, settings.budget_s, str(run_dir),
                      settings.move_threshold, None if settings.config_path is None else str(settings.config_path))
    (run_dir / "spec.json").write_text(json.dumps(asdict(spec), indent=2))
    started = time.monotonic()
    answer = workers.run(run_dir / "spec.json", settings.run_timeout_s)
    wall = time.monotonic() - started
    if answer is None or workers.stopping:
        return None  # interrupted: not a result, redone on resume
    if answer == "ok" and (run_dir / "summary.json").is_file():
        return make_row(run, world, json.loads((run_dir / "summary.json").read_text()), wall)
    return make_row(run, world, None, wall, answer.removeprefix("error: "))


SETTINGS_FILE = "sweep.json"  # in --out: the settings its rows ran with, beside results.csv
CODE_KEY = "code"  # in sweep.json: every version of the code its rows ran on, oldest first
INPUTS_KEY = "inputs"  # in sweep.json: digests of the world files, pictures and tables its rows ran with


def run_settings(settings: SweepSettings) -> dict:
    """What a run's numbers depend on besides its row's key: the search configuration as loaded (the
    same values from two files are the same settings), Θ_move and K."""
    config = load_config(SearchConfig, settings.config_path)
    return json.loads(json.dumps({"search": asdict(config), "move_threshold": settings.move_threshold,
                                  "budget_s": settings.budget_s}, default=str))


def run_inputs(prepared: dict[str, tuple[WorldFacts, Path, Path]]) -> dict:
    """What a run's numbers depend on besides the code and the settings: the bytes of each prepared
    world's file and of the target picture its planner reads, and of the detectability tables the
    planner ships. An edited world or a re-measured table under the same name would otherwise resume
    into a folder of rows made with the old ones."""
    worlds = {name: hashlib.sha1(world.path.read_bytes() + picture.read_bytes()).hexdigest()[:16]
              for name, (world, picture, _) in sorted(prepared.items())}
    tables = resources.files("offboard.perception.detection") / "tables"
    return {"worlds": worlds, "tables": {f.name: hashlib.sha1(f.read_bytes()).hexdigest()[:16]
                                         for f in sorted(tables.iterdir(), key=lambda f: f.name)
                                         if f.name.endswith(".json")}}


def _checked_inputs(recorded: dict, prepared: dict[str, tuple[WorldFacts, Path, Path]], out: Path) -> dict:
    """The inputs to record (those held, updated with this sweep's); refuses (:class:`SweepRefused`)
    inputs the folder holds with other bytes. Only the worlds with runs to do are compared: a world
    whose runs are all done mixes nothing."""
    held, now = recorded.get(INPUTS_KEY, {}), run_inputs(prepared)
    changed = [f"{kind[:-1]} {name}: {held[kind][name]} there, {digest} now"
               for kind in ("worlds", "tables") for name, digest in now[kind].items()
               if name in held.get(kind, {}) and held[kind][name] != digest]
    if changed:
        raise SweepRefused(f"{out} holds runs made with other inputs ({'; '.join(changed)}): use another --out")
    return {"worlds": {**held.get("worlds", {}), **now["worlds"]}, "tables": now["tables"]}


def _flat(tree: dict, prefix: str = "") -> dict[str, object]:
    out = {}
    for name, value in tree.items():
        out.update(_flat(value, f"{prefix}{name}.") if isinstance(value, dict) else {prefix + name: value})
    return out


def _checked_settings(settings: SweepSettings) -> dict:
    """The sweep's settings, to record in ``--out`` once it starts; refuses (:class:`SweepRefused`) a
    folder whose rows ran with others: their figures would be mixed in one report, silently. The code
    is recorded too, each version its rows ran on, with a warning when it changed (a commit of docs
    changes no figure, so that is not refused)."""
    path, now, current = settings.out / SETTINGS_FILE, run_settings(settings), code_version()
    codes, held = [], {}
    if path.is_file():
        try:
            recorded = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:  # cut short by a kill, say
            raise SweepRefused(f"{path} is not the settings file this harness writes ({exc}): use another --out") from None
        if not isinstance(recorded, dict):
            raise SweepRefused(f"{path} is not the settings file this harness writes (not a JSON object): "
                               "use another --out")
        codes = recorded.pop(CODE_KEY, [])
        held = recorded.pop(INPUTS_KEY, {})  # compared once the worlds are prepared (_checked_inputs)
        if not held:
            log.warning("%s records no inputs (it is older than that record): its runs are taken to have these", path)
        before, after = _flat(recorded), _flat(now)
        differ = [f"{k} {before.get(k)!r} there, {after.get(k)!r} now" for k in sorted(before.keys() | after.keys())
                  if before.get(k) != after.get(k)]
        if differ:
            raise SweepRefused(f"{settings.out} holds runs with other settings ({'; '.join(differ)}): "
                               "use another --out")
        others = [c for c in codes if c != current]
        if others:
            log.warning("%s: its rows ran on code %s; this sweep runs %s", settings.out, ", ".join(others), current)
    elif (settings.out / "results.csv").is_file():
        log.warning("%s has no %s: its runs are taken to have these settings", settings.out, SETTINGS_FILE)
    return {**now, INPUTS_KEY: held, CODE_KEY: codes if current in codes else [*codes, current]}


def code_version() -> str:
    """``git describe --always --dirty`` of the checkout the harness runs from, or "unknown"."""
    try:
        done = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=Path(__file__).resolve().parent,
                              capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    return done.stdout.strip() if done.returncode == 0 and done.stdout.strip() else "unknown"


def sweep(runs: list[Run], settings: SweepSettings, on_progress: Callable[[Progress], None] | None = None) -> Progress:
    """Run what ``results.csv`` does not hold yet; each row is appended as its run finishes."""
    settings.out.mkdir(parents=True, exist_ok=True)
    recorded = _checked_settings(settings)
    results = settings.out / "results.csv"
    try:
        done = finished_keys(results)
    except ValueError as exc:  # not this harness's results.csv: its rows are kept, no run is added
        raise SweepRefused(str(exc)) from None
    todo = [r for r in runs if r.key not in done]
    progress = Progress(total=len(runs), skipped=len(runs) - len(todo))
    prepared = _prepare(todo, settings.out)
    recorded[INPUTS_KEY] = _checked_inputs(recorded, prepared, settings.out)
    if todo:  # only now, and only with runs to do: the folder is bound to settings and code its runs have
        written = settings.out / (SETTINGS_FILE + ".new")
        written.write_text(json.dumps(recorded, indent=2) + "\n")
        written.replace(settings.out / SETTINGS_FILE)  # at once: a kill leaves the old file or the new one
    workers = _Workers(settings.jobs, settings.out / "workers")
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
    workers.close()
    return progress


# --- the command line ------------------------------------------------------------------------------

PRESETS = {"paper": PAPER}
# tables: the knowledge prior (hints above the surfaces targets stand on); surfaces, saliency: search --prior
# kinds that need no given knowledge (report §3.4 types 2 and 4)
PRIORS = ("uniform", "tables", "surfaces", "saliency")


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
                        help="results.csv, report.md, plots and one folder per run; a rerun resumes (default: experiment-out)")
    parser.add_argument("--preset", choices=sorted(PRESETS), default="paper",
                        help="the grid to start from (paper: the report's 160 runs); the options below override it")
    parser.add_argument("--baselines", action="store_true", help="add every baseline to the methods")
    parser.add_argument("--worlds", type=_list(str), metavar="W,..",
                        help=f"bundled world names, world files, folders of world files or suites ({', '.join(suite_names())})")
    parser.add_argument("--costs", type=_list(int, (1, 2, 3, 4)), metavar="C,..")
    parser.add_argument("--priors", type=_list(str, PRIORS), metavar="P,..", help=", ".join(PRIORS))
    parser.add_argument("--seeds", type=_list(int), metavar="S,..", help="simulator seeds (and the random baseline's)")
    parser.add_argument("--methods", type=_list(str, ("syt", *BASELINE_METHODS)), metavar="M,..",
                        help=f"syt, {', '.join(BASELINE_METHODS)}")
    parser.add_argument("--starts", type=number("--starts", 1, 10_000, int), metavar="N",
                        help="robot starts per world (derived from the world)")
    parser.add_argument("--targets", type=number("--targets", 1, 10_000, int), metavar="N",
                        help="target placements per world (its own, then on its tables)")
    parser.add_argument("--start", type=floats(3, "--start"), action="append", metavar="X,Y,HEADING_DEG",
                        help="use these robot starts instead (repeatable)")
    parser.add_argument("--target", type=floats(4, "--target"), action="append", metavar="X,Y,Z,YAW_DEG",
                        help="use these target placements instead (repeatable)")
    parser.add_argument("--jobs", type=number("--jobs", 1, 1024, int), default=os.cpu_count() or 1, metavar="N",
                        help="runs at once (default: the number of CPUs)")
    parser.add_argument("--budget-s", type=float, metavar="SECONDS",
                        help="robot-time budget K (default: the --config file's, 1800)")
    parser.add_argument("--move-threshold", type=probability("--move-threshold"), metavar="P",
                        help="Θ_move for the SYT runs, which then move by the report's threshold rule "
                             "(default: the rate rule); a folder swept with another is refused")
    parser.add_argument("--config", type=Path, metavar="FILE.toml",
                        help="search configuration (SearchConfig) for every run; a folder swept with another "
                             "is refused")
    parser.add_argument("--limit", type=number("--limit", 1, 10**9, int), metavar="N",
                        help="only the first N runs of the grid")
    parser.add_argument("--run-timeout-s", type=number("--run-timeout-s", 1.0, 1e7), default=3600.0, metavar="SECONDS",
                        help="wall clock per run")
    parser.add_argument("--report-only", action="store_true", help="rewrite report.md and the plots from results.csv")
    parser.add_argument("--rescore", action="store_true",
                        help="make results.csv's shortest paths and SPL again with this code's yardstick (for rows "
                             "made before it changed), then rewrite the report; runs nothing")


def grid_from_args(args: argparse.Namespace) -> GridSpec:
    spec = PRESETS[args.preset]
    given = {"worlds": args.worlds and expand_suites(args.worlds), "costs": args.costs, "priors": args.priors,
             "seeds": args.seeds, "methods": args.methods, "starts": args.starts, "targets": args.targets,
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
    failed, sweep_figures = 0, None
    if args.rescore and (args.out / "results.csv").is_file():
        try:
            log.info("%s: SPL changed in %d rows", args.out / "results.csv", rescore(args.out))
        except (ValueError, KeyError, OSError) as exc:
            log.error("cannot rescore %s: %s", args.out, exc)
            return 2
    elif not args.report_only:
        try:
            runs = build_runs(grid_from_args(args))
            if args.config:
                load_config(SearchConfig, args.config)  # refuse a broken file before any run starts
        except (ValueError, OSError, KeyError, tomllib.TOMLDecodeError) as exc:
            log.error("cannot start the sweep: %s", exc)
            return 2
        runs = runs[:args.limit] if args.limit else runs
        log.info("%d runs into %s, %d at a time", len(runs), args.out, args.jobs)
        started = time.monotonic()
        signal.signal(signal.SIGTERM, _interrupt)  # stop the workers and their agents, as on Ctrl-C
        try:
            settings = SweepSettings(args.out, args.jobs, args.budget_s, args.run_timeout_s, args.move_threshold,
                                     args.config)
            progress = sweep(runs, settings, _show)
        except SweepRefused as exc:
            log.error("cannot start the sweep: %s", exc)
            return 2
        except KeyboardInterrupt:
            sys.stderr.write("\ninterrupted: run the same command again to resume\n")
            return 130
        sys.stderr.write("\n")
        failed, wall_s = progress.failed, time.monotonic() - started
        log.info("%d runs done, %d failed, %d already done, in %.0f s", progress.done, failed, progress.skipped, wall_s)
        sweep_figures = (progress.done + progress.failed, wall_s, args.jobs)
    if not (args.out / "results.csv").is_file():
        log.error("no results in %s: nothing to report", args.out)
        return 2
    try:
        written = write_report(args.out / "results.csv", args.out, sweep_figures)
    except (ValueError, KeyError, OSError) as exc:  # a malformed results.csv or looks.jsonl: say which, keep them
        log.error("cannot write the report in %s: %s", args.out, exc)
        return 2
    for path in written:
        log.info("wrote %s", path)
    return 0 if failed == 0 else 1


if __name__ == "__main__":  # a worker: python -m offboard.experiments.harness --serve LOG_DIR
    if sys.argv[1:2] != ["--serve"] or len(sys.argv) != 3:
        sys.exit("usage: python -m offboard.experiments.harness --serve LOG_DIR (the sweep starts its workers itself)")
    sys.exit(_serve(Path(sys.argv[2])))
