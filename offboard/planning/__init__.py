"""The SYT planner, pure: target belief (eq. 1, 4 and §3.2's P[F]), the detection function of a look, sensed
spheres, expected detection of every action, the time model, where to look and where to move
(eq. 3, 9-12) and the priors of §3.4.

Pure: no I/O, no Zenoh, no Rerun. May import: ``shared`` and ``offboard.perception`` (the occupancy
grid, voxel grid and detectability tables it reasons over).
"""
