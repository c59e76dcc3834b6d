"""Fuzzing every decoder (``syt-offboard fuzz``): the planner side's own targets (the search
configuration, the hints file), the run of all targets with the onboard ones in a subprocess, and
the live fuzz of a running agent over Zenoh.

May import ``shared`` and every ``offboard`` subpackage but ``bench`` (never onboard: its targets run as ``python -m
onboard.fuzz``). Hypothesis, a test extra, is imported only once a fuzz run starts.
"""
