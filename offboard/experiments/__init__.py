"""Experiments: parallel, resumable sweeps of searches over worlds, the facts of a world that only
the experimenter may know, baselines, the report, and two sweeps compared run for run.

May import: everything in ``offboard`` below it (``robot`` … ``search``) and ``shared``.
"""
