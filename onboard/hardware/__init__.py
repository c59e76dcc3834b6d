"""Serial and USB hardware backends of the onboard devices (Pioneer base, PTU-D46, stereo camera).

Each driver implements a Protocol of ``onboard.devices`` over pyserial or OpenCV. These modules
import ``shared``, ``onboard.devices`` and ``onboard.config`` (where their settings live) only, never
the simulator or the emulators: a robot runs them without either (``tests/test_architecture.py``
checks it).
"""
