"""The one place that turns a configuration into the robot's devices, for either backend.

``backend = "sim"``: the simulator (``onboard.sim.robot``), with its ``SimControl``.

``backend = "hardware"``: a Pioneer over ARCOS, a PTU-D46 and a UVC stereo camera
(``[hardware.*]``). A device set to ``"sim"`` is simulated in the world of ``[sim]`` instead, on the
same wall clock, so a robot with only some real devices runs. A simulated camera renders that world
from the best pose it has: the emulated robot's truth when ``[hardware] truth`` names the socket of
``syt-onboard emulate`` (the world then is the emulator's), the simulated base's true pose, or
else the real base's odometry; and from the head's angles likewise.

The odometry of a real base starts at the world's start pose (``--start`` overrides it): the
planner works in the room's frame, so the robot must be told where it stands.
"""

from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import dataclass

from onboard.config import OnboardConfig
from onboard.devices import Base, Devices, PanTilt, SimControl, StereoCamera
from onboard.emulators.truth import TruthLink
from onboard.hardware.pioneer import PioneerBase
from onboard.hardware.ptu import PtuPanTilt
from onboard.hardware.uvc_camera import UvcStereoCamera
from onboard.sim.base import SimBase
from onboard.sim.clock import SimClock
from onboard.sim.pantilt import SimPanTilt
from onboard.sim.render import StereoRenderer
from onboard.sim.robot import SimStereoCamera, build_sim_robot
from shared.geometry import Pose2D
from shared.world import World

log = logging.getLogger(__name__)


@dataclass
class Robot:
    devices: Devices
    sim: SimControl | None  # the simulator's own controls; None for the hardware backend


def build_robot(config: OnboardConfig, world: World) -> Robot:
    """The configured backend's devices; a device that cannot be opened raises (``DeviceFault``,
    ``PtuError``, ``CalibrationFileError``) naming it, after closing those already open."""
    if config.backend == "sim":
        robot = build_sim_robot(config, world)
        return Robot(robot.devices, robot)
    return _build_hardware(config, world)


class _OdometryAsTruth:
    """A real base's odometry, where a simulated camera wants the true pose."""

    def __init__(self, base: Base):
        self._base = base

    @property
    def true_pose(self) -> Pose2D:
        return self._base.reading().pose


def _build_hardware(config: OnboardConfig, world: World) -> Robot:
    hw, sim = config.hardware, config.sim
    truth = TruthLink(hw.truth) if hw.truth else None
    if truth is not None:
        world = truth.placement().load(config.base.radius_m)
        log.info("world %r from the emulator's truth link %s", world.name, hw.truth)
    clock = SimClock(realtime=True)  # the robot's clock is the wall clock
    with contextlib.ExitStack() as opened:
        base: Base
        if hw.base.port == "sim":
            base = SimBase(world, config.base, clock, sim.odometry_noise, seed=sim.seed, step_s=sim.step_s)
        else:
            base = PioneerBase(hw.base, config.base, start=world.start)
        opened.callback(base.close)
        pantilt: PanTilt
        if hw.pantilt.port == "sim":
            pantilt = SimPanTilt(config.pantilt, clock, step_s=sim.step_s)
        else:
            pantilt = PtuPanTilt(hw.pantilt, config.pantilt)
        opened.callback(pantilt.close)
        camera = _camera(config, world, clock, base, pantilt, truth)
        opened.pop_all()
    log.info("hardware backend: base %s, pan-tilt %s, camera %s", hw.base.port, hw.pantilt.port, hw.camera.device)
    return Robot(Devices("hardware", clock, base, pantilt, camera), None)


def _camera(config: OnboardConfig, world: World, clock: SimClock, base: Base, pantilt: PanTilt,
            truth: TruthLink | None) -> StereoCamera:
    hw = config.hardware
    if hw.camera.device != "sim":
        return UvcStereoCamera(hw.camera, config.camera.mount())
    if isinstance(base, SimBase):
        pose_source = base
    else:
        pose_source = truth if truth is not None else _OdometryAsTruth(base)
    head_source = pantilt if isinstance(pantilt, SimPanTilt) or truth is None else truth
    renderer = StereoRenderer(world, config.camera.intrinsics(), config.camera.mount())
    started = time.monotonic()
    renderer.render(world.start, 0.0, 0.0)  # compile (or load) the kernels before the agent is ready
    log.info("simulated camera ready in %.1f s, rendering %r", time.monotonic() - started, world.name)
    return SimStereoCamera(renderer, pose_source, head_source, clock, config.timing)
