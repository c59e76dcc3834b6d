"""Byte-level emulators of the robot's serial devices, served on pseudo-terminals.

They speak the devices' wire protocols and move the simulator's physics, so the real serial
drivers (``onboard.hardware``) and the vendor's own clients can be tested without the robot.

May import: ``shared``, ``onboard.devices``/``onboard.config``, the simulator's physics (``onboard.sim``)
and the drivers' wire protocols (``onboard.hardware``). ``onboard.backends`` imports ``truth.py``,
the link over which simulated devices follow an emulated robot.
"""
