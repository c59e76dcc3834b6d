"""The search: the loop of look, update, decide and move; one run from the command line; the Rerun
recording and the top view.

May import: ``shared``, ``offboard.robot``, ``offboard.perception``, ``offboard.planning`` and
``offboard.navigation``; never the experiments or the benchmarks.
"""
