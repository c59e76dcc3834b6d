"""Key expressions: an id becomes exactly one key chunk."""

from __future__ import annotations

import pytest

from shared.keys import RobotKeys, check_robot_id


@pytest.mark.parametrize("robot_id", ["", "a/b", "a*", "a$", "abc\n", "x" * 65])
def test_an_id_that_is_not_one_plain_chunk_is_refused(robot_id):
    with pytest.raises(ValueError, match="must be 1-64 letters"):
        check_robot_id(robot_id)


def test_a_plain_id_names_the_robot_s_keys():
    assert check_robot_id("pioneer-3_a") == "pioneer-3_a"
    assert check_robot_id("x" * 64) == "x" * 64  # the longest allowed
    assert RobotKeys("pioneer-3_a").look.startswith("syt/pioneer-3_a/")
