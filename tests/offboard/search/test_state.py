"""The search's bookkeeping of the settings looked at from where the robot stands."""

from __future__ import annotations

from offboard.search.loop import SearchState


def test_a_setting_is_taken_once_from_a_position():
    state = SearchState()
    state.took(3, located=False)
    assert state.taken == {3}


def test_a_located_detection_is_confirmed_from_the_same_view_once_and_only_once():
    state = SearchState()
    state.took(5, located=True)
    assert 5 not in state.taken  # free to look again: a second image confirms it
    state.took(5, located=True)
    assert 5 in state.taken  # a third image of the same view would say nothing new


def test_moving_makes_every_setting_new_again():
    state = SearchState()
    state.took(5, located=True)
    state.took(5, located=True)
    state.took(2, located=False)
    state.moved()
    assert not state.taken
    state.took(5, located=True)
    assert 5 not in state.taken
