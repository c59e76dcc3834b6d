"""The agent on the robot: it serves the devices over Zenoh and keeps the robot safe.

``agent.py`` serves the ``Protocol`` devices of ``devices.py``; the backend behind them is chosen by
config: ``sim/`` (a simulated robot rendering real stereo pairs) or ``hardware/`` (serial and USB
devices). Imports ``shared``, never ``offboard``.
"""
