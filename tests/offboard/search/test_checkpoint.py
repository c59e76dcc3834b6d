"""Checkpoint and resume: the file gives back the belief, the map and the tracker bit for bit, and a
search whose planner is SIGKILLed carries on with ``--resume`` and finds the target."""

from __future__ import annotations

import dataclasses
import json
import math
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import bundled_picture, saved_and_read, search_on
from offboard.bench.safety import Observer
from offboard.navigation.localization import PoseTracker
from offboard.perception.detection import TargetModel
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.belief import TargetBelief
from offboard.planning.planner import Decision
from offboard.search import checkpoint
from offboard.search.checkpoint import CheckpointError
from offboard.search.loop import SearchConfig, SearchState
from offboard.search.run import SearchRequest, dynamic_priors
from offboard.search.top_view import LookTrace
from onboard.sim.textures import load_picture
from shared.geometry import Pose2D
from shared.launch import onboard_agent
from shared.transport import TransportConfig

GRID = VoxelGrid((2.0, 1.5, 1.0), 0.1)


def _looked_at(seed: int) -> tuple[TargetBelief, OccupancyGrid]:
    """A belief after misses that each saw part of the grid from some facings, and a map with hits."""
    rng = np.random.default_rng(seed)
    belief = TargetBelief(GRID, facing_sectors=8, prob_outside=0.05, coarse_factor=2)
    for _ in range(6):
        seen = rng.choice(GRID.num_cubes, size=GRID.num_cubes // 3, replace=False)
        b = np.where(rng.uniform(size=(seen.size, 8)) < 0.4, rng.choice([0.2, 0.5, 0.9], (seen.size, 8)), 0.0)
        belief.update_after_miss(seen, b)
    belief.rule_out_empty(rng.uniform(size=GRID.shape) < 0.2, 0.05)
    belief.rule_out_blocked_facings(rng.uniform(size=GRID.shape) < 0.05, 0.15, 0.3, 0.1)
    occupancy = OccupancyGrid(GRID)
    with occupancy.edit() as (log_odds, observed):
        log_odds.flat[rng.choice(GRID.num_cubes, 300)] = rng.uniform(-2, 3.5, 300).astype(np.float32)
        observed[log_odds != 0] = True
        observed.flat[:40] = True  # observed, log-odds back at exactly 0
    return belief, occupancy


def _saved_and_read(tmp_path: Path, belief: TargetBelief, occupancy: OccupancyGrid) -> checkpoint.Checkpoint:
    header, arrays = checkpoint.encode_maps(belief.state(), occupancy.log_odds, occupancy.observed)
    header.update(request={}, transport={}, config={}, wall_time_s=0.0, search={})  # the maps are under test
    checkpoint.write_file(tmp_path / checkpoint.FILE_NAME, header, arrays)
    return checkpoint.read(tmp_path)


def test_the_belief_and_the_map_read_back_bit_for_bit(tmp_path):
    belief, occupancy = _looked_at(1)
    state, odds, observed = checkpoint.decode_maps(_saved_and_read(tmp_path, belief, occupancy))
    saved = belief.state()
    for name in ("mass", "coarse", "seen_empty", "facing_blocked"):
        assert state[name].dtype == saved[name].dtype and np.array_equal(state[name], saved[name])
    assert {k: state[k] for k in ("outside", "scale", "stored_total", "success_prob")} == \
        {k: saved[k] for k in ("outside", "scale", "stored_total", "success_prob")}
    assert np.array_equal(odds.view(np.uint32), occupancy.log_odds.view(np.uint32))
    assert np.array_equal(observed, occupancy.observed)


def test_a_restored_belief_goes_on_exactly_as_the_original(tmp_path):
    belief, occupancy = _looked_at(2)
    state, _, _ = checkpoint.decode_maps(_saved_and_read(tmp_path, belief, occupancy))
    resumed = TargetBelief(GRID, facing_sectors=8, prob_outside=0.05, coarse_factor=2)
    resumed.restore(state)
    seen = np.arange(0, GRID.num_cubes, 3)
    b = np.full((seen.size, 8), 0.3, np.float32)
    assert resumed.update_after_miss(seen, b) == belief.update_after_miss(seen, b)
    empty = np.random.default_rng(5).uniform(size=GRID.shape) < 0.3  # partly seen empty before: once per cube
    assert resumed.rule_out_empty(empty, 0.05) == belief.rule_out_empty(empty, 0.05)
    solid = np.random.default_rng(6).uniform(size=GRID.shape) < 0.1  # partly solid before: once per facing
    assert resumed.rule_out_blocked_facings(solid, 0.15, 0.3, 0.1) == \
        belief.rule_out_blocked_facings(solid, 0.15, 0.3, 0.1)
    assert np.array_equal(resumed.state()["mass"], belief.state()["mass"])
    assert np.array_equal(resumed.coarse_mass(), belief.coarse_mass())
    assert resumed.success_prob == belief.success_prob and resumed.prob_outside == belief.prob_outside


def test_the_saved_states_cover_everything_the_belief_and_the_tracker_hold():
    """A field added to either without a place in its state() would be lost by a resume."""
    belief, _ = _looked_at(6)
    saved = belief.state()
    # given to the constructor, or derived; solid_done is a cache that restore() clears and the next
    # rule_out_blocked_facings rebuilds (test_a_restored_belief_goes_on_exactly_as_the_original)
    fixed = {"grid", "facing_sectors", "coarse_factor", "coarse_shape", "solid_done"}
    assert {name.lstrip("_") for name in vars(belief)} - fixed == set(saved)
    tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0))
    assert {name.lstrip("_") for name in vars(tracker)} - {"model"} == set(tracker.state())


def test_a_belief_of_another_shape_is_refused():
    belief, _ = _looked_at(3)
    other = TargetBelief(GRID, facing_sectors=4, prob_outside=0.05, coarse_factor=2)
    with pytest.raises(ValueError, match="belief mass"):
        other.restore(belief.state())


def test_the_pose_tracker_comes_back_with_its_correction():
    tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0))
    tracker.predict(Pose2D(1.0, 0.1, 0.2))
    assert tracker.correct(Pose2D(1.0, 0.1, 0.2), Pose2D(1.05, 0.12, 0.22), np.diag([1e-3, 1e-3, 1e-3]))
    tracker.predict(Pose2D(1.5, 0.2, 0.3))  # odometry after the correction: the offset stays
    resumed = PoseTracker(Pose2D(9.0, 9.0, 1.0))
    resumed.restore(json.loads(json.dumps(tracker.state())))
    later = Pose2D(2.0, 0.5, 0.4)
    assert resumed.world_pose(later) == tracker.world_pose(later)
    assert resumed.predict(later) == tracker.predict(later)
    assert np.array_equal(resumed.covariance, tracker.covariance)


def test_the_search_history_comes_back_as_it_was_views_included():
    state = SearchState(actions=3, positions=[(1.0, 2.0)], trail=[(0.5, 0.5), (1.0, 2.0)],
                        unreachable=[(2.5, 2.0)], taken={4, 1}, views=[(1.0, 2.0, 1), (3.5, 0.5, 7)], motion_s=12.5,
                        looks=[LookTrace(1.0, 2.0, 0.7, 30.0, 4.5, False)], estimate_m=np.array([3.0, 4.0, 0.8]))
    back = checkpoint.state_from_plain(json.loads(json.dumps(checkpoint.state_plain(state))))
    assert back.looks == state.looks and back.trail == state.trail and back.positions == state.positions
    assert isinstance(back.estimate_m, np.ndarray) and np.array_equal(back.estimate_m, state.estimate_m)
    state.estimate_m = back.estimate_m = None  # an array has no single truth for the dataclass's ==
    assert back == state


def test_the_request_comes_back_with_absolute_paths(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    request = SearchRequest(pictures=(Path("t.png"),), target_size_m=(0.2, 0.2, 0.3), room_m=(9.0, 5.0, 2.5),
                            priors=("uniform", "surfaces"), detectability=("sift=tables/s.json",),
                            out_dir=Path("out"), move_threshold=0.2)
    back = checkpoint.request_from_plain(json.loads(json.dumps(checkpoint.request_plain(request))))
    assert back.pictures == (tmp_path / "t.png",) and back.out_dir == tmp_path / "out"
    assert back.detectability == (f"sift={tmp_path / 'tables/s.json'}",)
    assert back == SearchRequest(**{**request.__dict__, "pictures": back.pictures, "out_dir": back.out_dir,
                                    "detectability": back.detectability})


def test_damaged_checkpoints_are_refused_naming_the_problem(tmp_path):
    belief, occupancy = _looked_at(4)
    _saved_and_read(tmp_path, belief, occupancy)
    path = tmp_path / checkpoint.FILE_NAME
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="ends before"):
        checkpoint.read(tmp_path)
    path.write_bytes(b"PK\x03\x04" + data[4:])
    with pytest.raises(CheckpointError, match="not a syt checkpoint"):
        checkpoint.read(tmp_path)
    with pytest.raises(CheckpointError, match="cannot read"):
        checkpoint.read(tmp_path / "elsewhere")
    header = {"version": checkpoint.VERSION, "request": {}}
    checkpoint.write_file(path, header, {})
    with pytest.raises(CheckpointError, match="transport: missing"):
        checkpoint.read(tmp_path)
    assert not list(tmp_path.glob(".*.tmp"))  # the atomic write left no temporary behind


def test_a_checkpoint_with_a_part_missing_or_mistyped_is_refused_naming_the_part(tmp_path):
    """Hand-edited, or from another version: each once escaped as a bare KeyError or TypeError."""
    belief, occupancy = _looked_at(4)
    header, arrays = checkpoint.encode_maps(belief.state(), occupancy.log_odds, occupancy.observed)
    header.update(request={}, transport={}, config={}, wall_time_s=0.0, search={})
    path = tmp_path / checkpoint.FILE_NAME
    short = {k: v for k, v in arrays.items() if k != "belief.mass.flags"}
    checkpoint.write_file(path, header, short)
    read = checkpoint.read(tmp_path)
    with pytest.raises(CheckpointError, match=r"maps: .*missing 'belief.mass.flags'"):
        checkpoint.decode_maps(read)
    with pytest.raises(CheckpointError, match=r"transport: .*missing 'zenoh_config'"):
        read.transport
    checkpoint.write_file(path, header, arrays)
    data = path.read_bytes()
    dtype = json.dumps(arrays["belief.coarse"].dtype.str).encode()  # "<f8": three characters
    path.write_bytes(data.replace(b'"dtype": ' + dtype, b'"dtype": "zzz"', 1))  # one numpy has not, as long
    with pytest.raises(CheckpointError, match=r"arrays\.belief\.\w+: .*TypeError"):
        checkpoint.read(tmp_path)
    checkpoint.write_file(path, {**header, "wall_time_s": None}, arrays)  # a TypeError, a KeyError escaped
    read = checkpoint.read(tmp_path)
    with pytest.raises(CheckpointError, match=r"wall_time_s: damaged"):
        read.wall_time_s
    with pytest.raises(CheckpointError, match=r"search\.state\.actions: .*missing 'state'"):
        read.actions
    data, start = path.read_bytes(), len(checkpoint.MAGIC)
    (length,) = struct.unpack_from("<Q", data, start)
    listed = {**json.loads(data[start + 8:start + 8 + length]), "arrays": [1, 2]}  # a list, not a table
    text = json.dumps(listed).encode()
    path.write_bytes(checkpoint.MAGIC + struct.pack("<Q", len(text)) + text + data[start + 8 + length:])
    with pytest.raises(CheckpointError, match=r"arrays: damaged or from another version"):
        checkpoint.read(tmp_path)

def test_the_command_line_says_what_is_missing(tmp_path):
    from offboard.cli import main

    with pytest.raises(SystemExit, match="--target-picture is required"):
        main(["search", "--connect", "tcp/127.0.0.1:1"])
    with pytest.raises(SystemExit, match="--resume: .*cannot read the checkpoint"):
        main(["search", "--resume", str(tmp_path)])


@pytest.mark.integration
def test_the_dynamic_priors_memory_comes_back(sim_agent, tmp_path):
    model = TargetModel((load_picture("target", Path(".")),), (0.23, 0.23, 0.23))
    grid = VoxelGrid(SearchConfig().room_m, SearchConfig().resolution_m)
    search = search_on(sim_agent[1], dynamic_priors(("surfaces", "saliency"), grid, model))
    search._look(Decision("look", "level", azimuth_rad=math.radians(90), tilt_rad=0.0, setting=0))
    surfaces, saliency = (prior.source.memory() for prior in search.dynamic_priors)
    assert surfaces.max() > 1.0 and saliency.max() > 1.0  # the look raised something for each
    saved = saved_and_read(tmp_path, search)
    resumed = search_on(sim_agent[1], dynamic_priors(("surfaces", "saliency"), grid, model))
    checkpoint.restore(resumed, saved)
    for before, prior in zip((surfaces, saliency), resumed.dynamic_priors):
        np.testing.assert_array_equal(prior.source.memory(), before)
    with_one_more = search_on(sim_agent[1], dynamic_priors(("surfaces", "saliency"), grid, model) * 2)
    with pytest.raises(CheckpointError, match="no memory for this search's dynamic prior"):
        checkpoint.restore(with_one_more, saved)


@pytest.mark.integration
def test_a_checkpoint_resumes_on_its_own_robot_only_and_not_after_that_robot_restarted(sim_agent, tmp_path):
    """The map and the pose offset are in the odometry frame of the robot as it ran: another robot id,
    or a clock behind the checkpoint's (its agent restarted, odometry and clock from zero), was resumed;
    and in the grid of the configuration it ran with."""
    search = search_on(sim_agent[1])
    search._look(Decision("look", "level", azimuth_rad=math.radians(90), tilt_rad=0.0, setting=0))
    saved = saved_and_read(tmp_path, search)
    checkpoint.restore(search_on(sim_agent[1]), saved)  # the same robot, its clock on: resumed
    part = saved.header["search"]
    for change, says in (({"robot_id": "pioneer2"}, "the checkpoint is of robot 'pioneer2'"),
                         ({"robot_clock_s": part["robot_clock_s"] + 600.0}, "the robot's agent restarted")):
        other = dataclasses.replace(saved, header={**saved.header, "search": {**part, **change}})
        with pytest.raises(CheckpointError, match=says):
            checkpoint.restore(search_on(sim_agent[1]), other)
    # run_search builds a resumed search from the checkpoint's own configuration; one built from another
    # (a config file edited since) would carry on with settings the saved part of the search never had
    edited = SearchConfig(planned_processing_s=0.5)
    with pytest.raises(CheckpointError, match="the search's configuration is not the checkpoint's"):
        checkpoint.restore(search_on(sim_agent[1], config=edited), saved)


# --- a killed planner, resumed ---------------------------------------------------------------------

START = "1.7,3.3,-90"  # paper-lab's target is 1.2 m behind the robot, on the bench to the north


def _wait_for_actions(out: Path, actions: int, process: subprocess.Popen, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert process.poll() is None, "the search ended before it could be killed"
        try:
            if checkpoint.read(out).actions >= actions:
                return
        except CheckpointError:  # not written yet
            pass
        time.sleep(0.05)
    raise AssertionError(f"no checkpoint with {actions} actions after {timeout_s} s")


def _started_search(endpoint: str, picture: Path, out: Path, stderr=subprocess.DEVNULL) -> subprocess.Popen:
    """A search for paper-lab's target (pictured on four sides) by the agent at ``endpoint``, in a
    process of its own."""
    return subprocess.Popen(
        [sys.executable, "-m", "offboard.cli", "search", "--connect", endpoint, "--no-multicast-scouting",
         "--target-picture", str(picture), "--target-sides", "4", "--room", "9,5,2.5", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=stderr, text=True)


@pytest.mark.long
@pytest.mark.integration
def test_a_search_killed_mid_way_resumes_from_its_checkpoint_and_finds_the_target(tmp_path):
    out, picture = tmp_path / "out", bundled_picture(tmp_path)
    with onboard_agent(["--backend", "sim", "--world", "paper-lab", "--start", START], tmp_path / "onboard.log") as agent:
        with TransportConfig(connect=(agent.endpoint,), multicast_scouting=False).open() as session:
            agent.wait_ready(session, "syt")
            search = _started_search(agent.endpoint, picture, out)
            try:
                _wait_for_actions(out, 2, search, timeout_s=60)
                search.send_signal(signal.SIGKILL)
                search.wait()
            finally:
                search.kill()
            saved = checkpoint.read(out)

            observer = Observer(session)
            deadline = time.monotonic() + 3.0
            while observer.state().base_moving and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not observer.state().base_moving
            before = observer.truth()
            time.sleep(0.5)
            after = observer.truth()
            assert math.hypot(after.x_m - before.x_m, after.y_m - before.y_m) < 1e-6
            assert after.heading_deg == pytest.approx(before.heading_deg, abs=1e-6)

            resumed = subprocess.run([sys.executable, "-m", "offboard.cli", "search", "--resume", str(out)],
                                     capture_output=True, text=True, timeout=120)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["found"] and summary["actions"] > saved.actions, summary
    assert np.linalg.norm(np.array(summary["target_estimate_m"]) - [1.7, 4.5, 0.865]) < 0.3, summary
    looks = (out / "looks.jsonl").read_text().splitlines()
    assert [json.loads(line)["action"] for line in looks] == list(range(1, summary["actions"] + 1))
    assert "resumed after action" in (out / "search.log").read_text()


@pytest.mark.integration
def test_a_robot_lost_mid_search_ends_it_with_one_error_and_keeps_its_checkpoint(tmp_path):
    """The failure that lost the robot is the one error said; that the stop sent after it could not
    reach the robot either is a warning."""
    out, picture = tmp_path / "out", bundled_picture(tmp_path)
    with onboard_agent(["--backend", "sim", "--world", "paper-lab", "--start", START], tmp_path / "onboard.log") as agent:
        with TransportConfig(connect=(agent.endpoint,), multicast_scouting=False).open() as session:
            agent.wait_ready(session, "syt")
        search = _started_search(agent.endpoint, picture, out, stderr=subprocess.PIPE)
        try:
            _wait_for_actions(out, 2, search, timeout_s=60)
            agent.process.kill()
            _, stderr = search.communicate(timeout=60)
        finally:
            search.kill()
    assert search.returncode == 1, stderr[-3000:]
    assert "Traceback" not in stderr and "--resume" in stderr
    errors = [line for line in stderr.splitlines() if " ERROR " in line]
    assert len(errors) == 1 and " syt.offboard: nobody answered" in errors[0], stderr[-3000:]
    assert "/stop" not in errors[0], "the failure to stop a lost robot hid the failure that lost it"
    assert checkpoint.read(out).actions >= 2 and not (out / "summary.json").exists()
