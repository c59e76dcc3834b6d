"""Byte-level emulators of the robot's serial devices, served on pseudo-terminals.

They speak the devices' wire protocols and move the simulator's physics, so the real serial
drivers (``onboard.hardware``) and the vendor's own clients can be tested without the robot.
"""
