"""What the recording shows of the maps: read back from the .rrd file Rerun wrote."""

from __future__ import annotations

import numpy as np
from rerun.chunk import RrdReader

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.belief import TargetBelief
from offboard.search.recording import MAX_PROBABLE_CUBES, Recorder
from shared.geometry import HeadMount, Intrinsics, Pose2D

GRID = VoxelGrid((3.0, 2.0, 1.5), 0.05)
K = Intrinsics.from_fov(640, 480, 66.0)


def _logged(rrd, entity: str, column: str) -> np.ndarray:
    for chunk in RrdReader(rrd).stream():
        if chunk.entity_path == entity:
            return np.array(chunk.to_record_batch().column(column).to_pylist()[0])
    raise AssertionError(f"nothing logged at {entity}")


def _maps_recorded(tmp_path, belief: TargetBelief, occupancy: OccupancyGrid):
    rrd = tmp_path / "maps.rrd"
    recorder = Recorder(path=rrd)
    recorder.log_maps(belief, occupancy)
    recorder.close()
    return rrd


def test_the_recording_shows_the_occupied_cubes_and_the_likeliest_ones_where_they_are(tmp_path):
    occupancy = OccupancyGrid(GRID)
    camera = HeadMount().camera_in_world(Pose2D(0.5, 1.0, 0.0), 0.0, 0.0)
    occupancy.integrate_disparity(np.full((480, 640), K.fx_px * 0.12 / 1.5, np.float32), K, 0.12, camera)
    weights = np.ones(GRID.shape)
    weights[40:43, 10:14, 15:17] = 50.0  # 24 cubes well above the average
    belief = TargetBelief(GRID, facing_sectors=4)
    belief.set_prior(weights, prob_outside=0.05)
    rrd = _maps_recorded(tmp_path, belief, occupancy)

    centres = GRID.centers()
    shown = _logged(rrd, "/world/occupancy", "Points3D:positions")
    assert len(shown) > 1000 and np.allclose(shown, centres[occupancy.occupied()], atol=1e-6)
    likeliest = GRID.index_of(_logged(rrd, "/world/target_prob", "Boxes3D:centers"))
    hot = {(i, j, k) for i in range(40, 43) for j in range(10, 14) for k in range(15, 17)}
    assert len(likeliest) == 24 and {tuple(int(v) for v in cube) for cube in likeliest} == hot


def test_the_recording_shows_at_most_its_share_of_likely_cubes_and_the_likeliest_first(tmp_path):
    rng = np.random.default_rng(0)
    weights = np.ones(GRID.shape)
    hot = rng.choice(GRID.num_cubes, 3 * MAX_PROBABLE_CUBES, replace=False)
    weights.flat[hot] = 10.0 + rng.random(hot.size)  # more cubes above the average than are shown
    belief = TargetBelief(GRID, facing_sectors=1)
    belief.set_prior(weights, prob_outside=0.0)
    rrd = _maps_recorded(tmp_path, belief, OccupancyGrid(GRID))
    likeliest = _logged(rrd, "/world/target_prob", "Boxes3D:centers")
    shown = np.unique(GRID.index_of(likeliest) @ np.array([GRID.shape[1] * GRID.shape[2], GRID.shape[2], 1]))
    best = hot[np.argsort(weights.flat[hot])[-MAX_PROBABLE_CUBES:]]
    assert len(likeliest) == MAX_PROBABLE_CUBES and set(shown) == set(best)


def test_the_recordings_log_panel_keeps_a_critical_records_level_and_its_traceback(tmp_path):
    """CRITICAL fell to the panel's DEBUG, and a logged exception lost its traceback."""
    import logging

    rrd = tmp_path / "log.rrd"
    recorder, logger = Recorder(path=rrd), logging.getLogger("syt.test.recording")
    recorder.attach_logging(logger)
    try:
        raise RuntimeError("the link is gone")
    except RuntimeError:
        logger.critical("robot lost", exc_info=True)
    recorder.detach_logging(logger)
    recorder.close()
    texts = [(row, level) for chunk in RrdReader(rrd).stream() if chunk.entity_path == "/logs"
             for batch in [chunk.to_record_batch()]
             for row, level in zip(batch.column("TextLog:text").to_pylist(), batch.column("TextLog:level").to_pylist())]
    (text, level), = [(t[0], lv[0]) for t, lv in texts if "robot lost" in t[0]]
    assert level == "ERROR" and "RuntimeError: the link is gone" in text


def test_the_position_map_lines_up_with_the_target_map(tmp_path):
    """The target map is drawn with y up and the positions were drawn with y down (Rerun's 2D
    default), so a position beside the likeliest column showed on the map's other side."""
    from offboard.planning.action_values import ActionValues

    grid = VoxelGrid((3.0, 2.0, 1.5), 0.05, origin_m=(1.0, -0.5, 0.0))
    weights = np.ones(grid.shape)
    weights[10, 30, :] = 1000.0  # one likely column, far from the map's middle
    belief = TargetBelief(grid, facing_sectors=1)
    belief.set_prior(weights, prob_outside=0.0)
    column_xy = grid.center_of(np.array([10, 30, 0]))[:2]
    rrd = tmp_path / "plan.rrd"
    recorder = Recorder(path=rrd)
    recorder.log_maps(belief, OccupancyGrid(grid))
    recorder.log_plan(ActionValues(np.zeros((2, 3)), np.array([1.0, 0.5, 0.0])),
                      np.array([column_xy, [2.0, 0.0]]), grid)
    recorder.close()

    image = _logged(rrd, "/maps/target_prob", "Image:buffer").astype(np.uint8)
    image = image.reshape(grid.shape[1], grid.shape[0])  # rows are y, columns x
    row, col = np.unravel_index(np.argmax(image), image.shape)
    points = _logged(rrd, "/maps/position_prob", "Points2D:positions")
    assert np.allclose(points[0], [col + 0.5, row + 0.5], atol=1e-6)
