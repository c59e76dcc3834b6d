"""The benchmarks: each prints one JSON object of medians.

May import: ``shared`` and every ``offboard`` subpackage but ``fuzz``.
"""
