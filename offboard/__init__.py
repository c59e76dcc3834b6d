"""The planner's side of syt, on the workstation.

Subpackages, in the order they may import each other (a test enforces it):

- ``robot``: talking to the onboard agent over Zenoh (:class:`RobotClient`, a scripted tour);
- ``perception``: stereo, the occupancy grid, target detection and its measured detectability;
- ``planning``: the SYT planner itself, pure (target belief, detection function, actions, priors);
- ``navigation``: driving on the mapped floor (Dijkstra, TangentBug, scan-matched localisation);
- ``search``: the search loop that ties them together, one run, the Rerun recording, the top view;
- ``experiments``: sweeps of searches over worlds, baselines, the report;
- ``bench``: the benchmarks;
- ``fuzz``: every decoder under Hypothesis, and a live agent fuzzed over Zenoh.

``bench`` and ``fuzz`` both sit on top and do not import each other.

Beside them, ``cli`` (the ``syt-offboard`` command) and ``kernel_cache`` (numba's cache filled before
any search needs it) may import any of them. Everything here imports ``shared``, never ``onboard``.
"""
