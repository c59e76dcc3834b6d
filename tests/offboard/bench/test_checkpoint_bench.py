"""bench checkpoint: one JSON object of figures, from a checkpoint that reads back exactly."""

from offboard.bench.checkpoint import run


def test_the_benchmark_writes_and_reads_back_a_5cm_checkpoint_exactly():
    figures = run(writes=2, looks=2)
    assert figures["exact"] and figures["cubes"] == 900_000 and figures["facing_sectors"] == 8
    assert 0 < figures["checkpoint_mb"] < figures["raw_mb"] / 3
    assert 0 < figures["checkpoint_encode_ms"] <= figures["checkpoint_write_ms"] <= figures["checkpoint_write_ms_max"]
