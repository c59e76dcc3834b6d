"""Driving on what the robot has mapped: Dijkstra distances, TangentBug, scan-matched odometry
correction, and the navigator that executes a move.

May import: ``shared``, ``offboard.robot`` and ``offboard.perception``; never the planner.
"""
