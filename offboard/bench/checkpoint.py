"""``syt-offboard bench checkpoint --json``: what a search's checkpoint costs after every action.

The state is a realistic one at the report's 5 cm with 8 facing sectors (a one-sided target): the
9 × 5 × 2.5 m room (900,000 cubes; the belief alone is 29 MB of float32), ten looks from around the
room, each putting a stereo frame into the map and a miss into the belief through the shipped SIFT
detectability table (then ruling out the space stereo saw empty, as the search does). A write is what the search does after an action: encode the belief and the
map, write the file with the plain state, fsync, rename, fsync the folder. Figures are medians:
of 15 writes, and of 5 reads (a resume reads once, but one read's time is mostly the machine's
mood).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from offboard.perception.detection.detector import shipped_table
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.belief import TargetBelief
from offboard.planning.detection_function import look_footprint, visible_depth
from offboard.search import checkpoint
from offboard.search.loop import SearchConfig, fold_in_map
from offboard.search.run import SearchRequest
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.transport import TransportConfig

log = logging.getLogger(__name__)

ROOM_M = (9.0, 5.0, 2.5)
K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()
LOOKS = 10
TARGET_M = 0.23  # the target's edge: the request's size, and its depth for the map's rule-outs


def realistic_state(looks: int = LOOKS, seed: int = 0) -> tuple[TargetBelief, OccupancyGrid]:
    """Belief and map after ``looks`` looks that missed, from random poses, pans and tilts."""
    grid = VoxelGrid(ROOM_M, 0.05)
    occupancy = OccupancyGrid(grid)
    belief = TargetBelief(grid, facing_sectors=8, prob_outside=0.05, coarse_factor=4)
    table = shipped_table("sift").for_sectors(belief.facing_sectors)
    rng = np.random.default_rng(seed)
    config = SearchConfig()
    for _ in range(looks):
        pose = Pose2D(rng.uniform(1.0, 8.0), rng.uniform(1.0, 4.0), rng.uniform(-math.pi, math.pi))
        camera = MOUNT.camera_in_world(pose, rng.uniform(-1.5, 1.5), rng.choice([-0.4, 0.0, 0.3]))
        # a wall of varied depth in front of the camera, so that the map and the footprint are uneven
        depth = rng.uniform(1.5, 5.0) + np.cumsum(rng.normal(0.0, 0.01, 640))
        disparity = np.repeat((K.fx_px * MOUNT.baseline_m / depth)[None, :], 480, axis=0).astype(np.float32)
        occupancy.integrate_disparity(disparity, K, MOUNT.baseline_m, camera)
        seen = visible_depth(disparity, occupancy, camera, K, MOUNT.baseline_m, 16, table.range_m[1])
        footprint = look_footprint(grid, camera, K, seen, 16, table, belief.facing_azimuths_rad, 0.12)
        belief.update_after_miss(footprint.cube_index, footprint.detection_prob)
        fold_in_map(belief, occupancy, config, TARGET_M)  # as the search does after every look
    return belief, occupancy


def _plain_parts(looks: int) -> dict:
    """The header's plain parts, the size of a real search's after ``looks`` looks."""
    log_entry = {"action": 1, "expected_p": 0.111406, "realised_p": 0.112968, "detected": False,
                 "processing_s": 1.0667, "motion_s": 0.5651, "x_m": 1.7, "y_m": 3.3, "setting": 2}
    request = SearchRequest(pictures=(Path("target.png"),), target_size_m=(TARGET_M,) * 3, room_m=ROOM_M)
    search = {"state": {"actions": looks, "look_log": [log_entry] * looks, "planning_ms": [400.0] * looks,
                        "trail": [[1.0, 2.0]] * looks}}
    return {"request": checkpoint.request_plain(request), "transport": checkpoint.transport_plain(TransportConfig()),
            "config": dataclasses.asdict(SearchConfig()), "wall_time_s": 60.0, "search": search}


def run(writes: int = 15, looks: int = LOOKS, reads: int = 5) -> dict:
    belief, occupancy = realistic_state(looks)
    encode_ms, write_ms, cpu_ms, sizes = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / checkpoint.FILE_NAME
        checkpoint.encode_maps(belief.state(), occupancy.log_odds, occupancy.observed)  # compile the kernels
        for _ in range(writes):
            started, cpu = time.perf_counter(), time.thread_time()
            header, arrays = checkpoint.encode_maps(belief.state(), occupancy.log_odds, occupancy.observed)
            header.update(_plain_parts(looks))
            encoded = time.perf_counter()
            sizes.append(checkpoint.write_file(path, header, arrays))
            done = time.perf_counter()
            encode_ms.append((encoded - started) * 1000.0)
            write_ms.append((done - started) * 1000.0)
            cpu_ms.append((time.thread_time() - cpu) * 1000.0)
        checkpoint.decode_maps(checkpoint.read(Path(tmp)))  # compile the decoder
        read_ms = []
        for _ in range(reads):
            started = time.perf_counter()
            state, odds, observed = checkpoint.decode_maps(checkpoint.read(Path(tmp)))
            read_ms.append((time.perf_counter() - started) * 1000.0)
    saved = belief.state()
    arrays = ("mass", "coarse", "seen_empty", "facing_blocked")
    exact = all(np.array_equal(state[k], saved[k]) for k in arrays) and \
        np.array_equal(odds, occupancy.log_odds) and np.array_equal(observed, occupancy.observed)
    raw = sum(saved[k].nbytes for k in arrays) + occupancy.log_odds.nbytes + occupancy.observed.nbytes
    return {
        "checkpoint_write_ms": round(float(np.median(write_ms)), 1),
        "checkpoint_write_ms_max": round(float(np.max(write_ms)), 1),
        "checkpoint_encode_ms": round(float(np.median(encode_ms)), 1),
        "checkpoint_write_cpu_ms": round(float(np.median(cpu_ms)), 1),  # without waiting for the disk or the CPU
        "checkpoint_read_ms": round(float(np.median(read_ms)), 1),
        "checkpoint_mb": round(sizes[-1] / 1e6, 2),
        "raw_mb": round(raw / 1e6, 2),
        "exact": bool(exact),
        "looks": looks,
        "cubes": occupancy.grid.num_cubes,
        "facing_sectors": belief.facing_sectors,
    }
