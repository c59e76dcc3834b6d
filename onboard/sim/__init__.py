"""The simulator backend: a differential-drive base, a PTU-D46-like head and a stereo camera that
renders real image pairs of a world file, on a clock that runs as fast as the machine allows.

May import: ``shared`` and ``onboard.devices``/``onboard.config``; never ``onboard.hardware``.
"""
