"""Talking to the robot: every onboard command as a method, and a scripted tour.

May import: ``shared`` only.
"""
