"""The simulator backend: a differential-drive base, a PTU-D46-like head and a stereo camera that
renders real image pairs of a world file, on a clock that runs as fast as the machine allows; and the
tools around it: world files generated and checked, previews, views with true depth to score stereo on.

May import: ``shared`` and ``onboard.devices``/``onboard.config``; never ``onboard.hardware`` or
``onboard.emulators`` (``tests/test_architecture.py`` checks it).
"""
