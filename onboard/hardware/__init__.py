"""Serial and USB hardware backends of the onboard devices (Pioneer base, PTU-D46, stereo camera).

Each driver implements a Protocol of ``onboard.devices`` over pyserial or OpenCV. These modules
import ``shared`` and ``onboard.devices`` only, never the simulator: a robot runs them without it.
"""
