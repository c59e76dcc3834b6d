"""What the robot and the workstation both need: messages, codec, key expressions, config loading,
geometry, transport, device limits and the world format. Imports neither ``onboard`` nor ``offboard``.
"""
