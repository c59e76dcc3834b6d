"""The benchmarks: each prints one JSON object of medians.

May import: anything in ``offboard`` and ``shared``.
"""
