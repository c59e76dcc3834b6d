"""What the cameras tell: stereo (scored on Middlebury and on rendered rooms), the 3D occupancy grid
(eq. 5-8), target detection, and the detectability tables measured for each detector.

May import: ``shared`` and ``offboard.robot`` (the detector calibration drives the simulated robot);
never the planner, navigation, the search or the experiments.
"""
