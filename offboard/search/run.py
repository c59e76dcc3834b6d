"""One search as a user runs it: build everything from the options, run, write the outputs.

Outputs in the ``--out`` folder: ``summary.json``, ``search.rrd`` (Rerun), ``search.png`` (top
view) and ``search.log``.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from offboard.planning import priors
from offboard.perception.detectability import DetectabilityTable
from offboard.perception.detection.detector import Detector, detector_names, make_detector, shipped_table
from offboard.perception.detection.target_model import TargetModel
from offboard.search.recording import Recorder
from offboard.robot.robot_client import CommandError, RobotClient, RobotUnavailable
from offboard.search.loop import Search, SearchConfig, build_prior, check_prior_spec
from offboard.perception.voxel_grid import VoxelGrid
from shared.config import load_config
from shared.geometry import Intrinsics
from shared.transport import TransportConfig

if TYPE_CHECKING:
    from offboard.search.checkpoint import Checkpoint

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SearchRequest:
    """One search's options. ``room_m``, ``cost``, ``budget_s``, ``move_threshold`` and ``detector``
    override the configuration file's values when given; None keeps the file's (or its default).
    A ``move_threshold`` also selects the report's move rule, the only one that reads it."""

    pictures: tuple[Path, ...]
    target_size_m: tuple[float, float, float]
    room_m: tuple[float, float, float] | None = None
    target_sides: int = 1  # pictured vertical faces: 1, or 4 (then it faces every camera: no facing to track)
    cost: int | None = None
    priors: tuple[str, ...] = ("uniform",)
    budget_s: float | None = None
    move_threshold: float | None = None
    detector: str | None = None
    detectability: tuple[str, ...] = ()  # NAME=FILE
    config_path: Path | None = None
    out_dir: Path = Path("search-out")
    spawn: bool = False
    viewer_url: str | None = None
    record: bool = True  # write search.rrd (experiments turn it off to save time and disk)
    checkpoint: bool = True  # write checkpoint.syt after every action (for --resume)

    def __post_init__(self) -> None:
        for spec in self.priors:  # a mistyped prior must not quietly become the uniform one
            check_prior_spec(spec)


def search_config(request: SearchRequest) -> SearchConfig:
    """The configuration file's search (or the defaults), with the options the request gives."""
    base = load_config(SearchConfig, request.config_path)
    threshold_rule = None if request.move_threshold is None else "threshold"
    planner = dataclasses.replace(base.planner, **_given(cost_function=request.cost, budget_s=request.budget_s,
                                                         move_threshold=request.move_threshold,
                                                         move_rule=threshold_rule))
    facing = {"facing_sectors": 1} if request.target_sides == 4 else {}
    return dataclasses.replace(base, planner=planner, **_given(room_m=request.room_m, detector=request.detector),
                               **facing)


def _given(**options) -> dict:
    return {name: value for name, value in options.items() if value is not None}


def detectability_table(name: str, detector: Detector, files: dict[str, Path]) -> DetectabilityTable:
    """The measured table: given on the command line, else the one shipped for the default target,
    else a nominal one over the detector's own range."""
    if name in files:
        return DetectabilityTable.load(files[name])
    if (shipped := shipped_table(name)) is not None:
        return shipped
    near, far = detector.range_m
    log.warning("no measured detectability table for %s: using a nominal one over %.2f-%.2f m", name, near, far)
    return DetectabilityTable.nominal(name, near_m=near, far_m=far, cost_ms=detector.cost_ms)


def build_detectors(detector: str, request: SearchRequest, model: TargetModel, intrinsics: Intrinsics) -> dict:
    """The detectors ``detector`` names ("auto": both), each with its detectability table for the
    target's size."""
    files = dict(detectability_file(spec) for spec in request.detectability)
    names = ("sift", "ncc") if detector == "auto" else (detector,)
    detectors = {}
    for name in names:
        detector = make_detector(name, model, intrinsics)
        detectors[name] = (detector, detectability_table(name, detector, files).for_face(model.face_size_m))
    return detectors


@dataclass(frozen=True)
class LookPrior:
    """A dynamic prior as the search calls it after every look: ``factor(obs, search)`` is the
    factor to reweight the belief by (None: none), ``source`` the prior, whose memory the checkpoint
    keeps."""

    source: priors.SupportSurfaces | priors.Saliency
    factor: Callable

    def __call__(self, obs, search):
        return self.factor(obs, search)


def dynamic_priors(specs: tuple[str, ...], grid: VoxelGrid, model: TargetModel) -> list[LookPrior]:
    """Type 2 (surfaces) and type 4 (saliency): factors applied to the belief after every look."""
    made = []
    if "surfaces" in specs:
        support = priors.SupportSurfaces(grid)
        made.append(LookPrior(support, lambda obs, search: support.update(search.occupancy)))
    if "saliency" in specs:
        saliency = priors.Saliency(model.pictures, grid)
        made.append(LookPrior(saliency, lambda obs, search: None if search.last_footprint is None else saliency.factor(
            obs.capture.left, search.last_footprint.cube_index, obs.camera_in_world, obs.intrinsics)))
    return made


def run_search(transport: TransportConfig, request: SearchRequest, policy=None, detector_cache: dict | None = None,
               resume: Checkpoint | None = None,
               after_action: Callable[[Search, RobotClient], None] | None = None) -> dict:
    """Run one search; ``policy`` (a factory taking the SearchPlanner) replaces the SYT decisions.
    ``detector_cache`` keeps the detectors (and their tables) for later searches of the same target
    with the same camera: building a SIFT model takes seconds. ``resume``: carry on from a
    checkpoint (the log is appended to, the recording goes to a new file). ``after_action``: the
    experimenter's hook after every action, before the checkpoint (the harness logs the simulator's
    true pose with it; the search itself never sees it)."""
    out = request.out_dir
    # what the user named is checked before --out is touched: a failed start must not wipe the last search's log
    config = search_config(request) if resume is None else resume.config
    model = TargetModel.from_files(request.pictures, request.target_size_m)
    from offboard.search.checkpoint import attach  # (it imports this module)

    out.mkdir(parents=True, exist_ok=True)
    file_log = logging.FileHandler(out / "search.log", mode="a" if resume else "w")
    file_log.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    root.addHandler(file_log)
    recorder = None
    try:  # from here on the log handler is ours to remove, whatever fails (a viewer that will not start)
        if request.record or request.spawn or request.viewer_url:
            rrd = "search.rrd" if resume is None else f"search-resumed-{resume.actions}.rrd"
            recorder = Recorder(out / rrd if request.record else None, spawn=request.spawn,
                                connect_url=request.viewer_url)
            recorder.attach_logging(root)
        with transport.open() as session, RobotClient(session, transport.robot_id) as robot:
            info = robot.wait_for_robot()
            intrinsics = info.intrinsics.to_intrinsics()
            cache = {} if detector_cache is None else detector_cache
            key = (config.detector, request.pictures, request.target_size_m, request.detectability, intrinsics)
            if key not in cache:
                cache[key] = build_detectors(config.detector, request, model, intrinsics)
            detectors = cache[key]
            grid = VoxelGrid(config.room_m, config.resolution_m)
            search = Search(robot, config, detectors, build_prior(grid, list(request.priors)),
                            dynamic_priors(request.priors, grid, model), recorder, model.size_m[0], policy)
            if request.checkpoint or resume:
                attach(search, request, transport, resume)
            if after_action:
                search.on_action = _chain(functools.partial(after_action, robot=robot), search.on_action)
            try:
                search.run()
            except BaseException:  # stop the robot, but tell the error that ended the search, not the stop's
                _stop_after_failure(robot)
                raise
            robot.stop()
            if resume:
                search.wall_time_s += resume.wall_time_s  # the summary covers the whole search
            summary = {**search.summary(), "prior": "+".join(request.priors)}
            search.write_top_view(out / "search.png")
            (out / "looks.jsonl").write_text("".join(json.dumps(look) + "\n" for look in search.state.look_log))
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        log.info("summary: %s", summary)
        return summary
    finally:
        if recorder:
            recorder.detach_logging(root)
            recorder.close()
        root.removeHandler(file_log)
        file_log.close()


def _stop_after_failure(robot: RobotClient) -> None:
    try:
        robot.stop()
    except (RobotUnavailable, CommandError) as exc:  # a robot that is gone cannot be stopped from here
        log.warning("could not stop the robot after the search failed: %s", exc)  # the failure is the error


def _chain(first: Callable[[Search], None], then: Callable[[Search], None] | None) -> Callable[[Search], None]:
    def both(search: Search) -> None:
        first(search)
        if then:
            then(search)
    return both


def detectability_file(spec: str) -> tuple[str, Path]:
    """``--detectability NAME=FILE``: the detector's name and its table's file (not read here)."""
    name, sep, path = spec.partition("=")
    if not sep or name not in detector_names():  # a mistyped name's table would be ignored, unsaid
        raise ValueError(f"--detectability takes NAME=FILE with NAME one of {', '.join(detector_names())}, "
                         f"not {spec!r}")
    return name, Path(path)

