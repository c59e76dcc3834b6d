"""The simulated robot: a base, a pan-tilt unit and a stereo camera sharing one world and clock."""

from __future__ import annotations

import logging
import time

from onboard.config import OnboardConfig
from onboard.devices import Devices, StereoImages
from onboard.sim.base import SimBase
from onboard.sim.clock import SimClock
from onboard.sim.pantilt import SimPanTilt
from onboard.sim.render import StereoRenderer
from onboard.sim.world import World
from shared.limits import CameraTiming

log = logging.getLogger(__name__)


class SimStereoCamera:
    """Renders the pair from the *true* pose; the agent stamps it with the odometry pose."""

    def __init__(self, renderer: StereoRenderer, base: SimBase, pantilt: SimPanTilt,
                 clock: SimClock, timing: CameraTiming):
        self.intrinsics = renderer.intrinsics
        self.mount = renderer.mount
        self._renderer = renderer
        self._base = base
        self._pantilt = pantilt
        self._clock = clock
        self._timing = timing

    def capture(self) -> StereoImages:
        head = self._pantilt.reading()
        frame = self._renderer.render(self._base.true_pose, head.pan_rad, head.tilt_rad)
        self._clock.advance(self._timing.capture_s)
        return StereoImages(frame.left, frame.right)

    def close(self) -> None:
        pass


def build_sim_devices(config: OnboardConfig, world: World) -> Devices:
    sim = config.sim
    clock = SimClock(realtime=sim.realtime)
    base = SimBase(world, config.base, clock, sim.odometry_noise, seed=sim.seed, step_s=sim.step_s)
    pantilt = SimPanTilt(config.pantilt, clock, step_s=sim.step_s)
    renderer = StereoRenderer(world, config.camera.intrinsics(), config.camera.mount())
    started = time.monotonic()
    renderer.render(world.start, 0.0, 0.0)  # compile (or load) the kernels before the agent says it is ready
    log.info("renderer ready in %.1f s", time.monotonic() - started)
    camera = SimStereoCamera(renderer, base, pantilt, clock, config.timing)
    log.info("simulated robot in world %r at (%.2f, %.2f), %s clock", world.name, world.start.x_m,
             world.start.y_m, "real-time" if sim.realtime else "fast")
    return Devices("sim", clock, base, pantilt, camera)
