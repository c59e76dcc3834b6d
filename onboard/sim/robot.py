"""The simulated robot: a base, a pan-tilt unit and a stereo camera sharing one world and clock,
and the simulator's own controls (the true pose, teleporting, a fresh run) for tests, calibration
and experiment sweeps."""

from __future__ import annotations

import logging
import time
from typing import Protocol

from onboard.config import OnboardConfig
from onboard.devices import Devices, PanTiltReading, StereoImages
from onboard.sim.base import SimBase
from onboard.sim.clock import SimClock
from onboard.sim.faults import FaultInjector
from onboard.sim.pantilt import SimPanTilt
from onboard.sim.render import StereoRenderer
from shared.world import World, WorldError
from shared.geometry import Pose2D
from shared.limits import CameraTiming

log = logging.getLogger(__name__)


class TruePose(Protocol):
    """Where a simulated camera stands: a simulated base, or what stands in for one."""

    @property
    def true_pose(self) -> Pose2D: ...


class HeadAngles(Protocol):
    def reading(self) -> PanTiltReading: ...


class SimStereoCamera:
    """Renders the pair from the *true* pose; the agent stamps it with the odometry pose."""

    def __init__(self, renderer: StereoRenderer, base: TruePose, pantilt: HeadAngles,
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

    def show(self, world: World) -> None:
        """Render ``world`` from now on (a new target placement)."""
        self._renderer = StereoRenderer(world, self.intrinsics, self.mount)

    def close(self) -> None:
        pass


class SimRobot:
    """The simulated devices and the :class:`onboard.devices.SimControl` over them."""

    def __init__(self, world: World, devices: Devices, base: SimBase, pantilt: SimPanTilt,
                 camera: SimStereoCamera, faults: FaultInjector) -> None:
        self.world, self.devices = world, devices
        self._base, self._pantilt, self._camera = base, pantilt, camera
        self._faults = faults

    @property
    def true_pose(self) -> Pose2D:
        return self._base.true_pose

    def teleport(self, pose: Pose2D) -> str | None:
        return self._base.teleport(pose)

    def inject_fault(self, device: str, after_s: float) -> None:
        self._faults.arm(device, after_s)

    def reset(self, start: Pose2D, target_m: tuple[float, float, float], target_yaw_deg: float,
              seed: int) -> str | None:
        """A new run: target moved, robot at ``start`` with its head centred, noise reseeded. The
        reason if the placement is impossible (nothing changes then)."""
        try:
            world = self.world.with_target(*target_m, target_yaw_deg).with_start(
                start.x_m, start.y_m, start.heading_rad)
        except WorldError as exc:
            return str(exc)
        problem = self._base.teleport(start, world)
        if problem:
            return problem
        self._base.reseed(seed)
        self._pantilt.home()
        self._camera.show(world)
        self.world = world
        log.info("new run: start (%.2f, %.2f), target at (%.2f, %.2f, %.2f) facing %.0f°, seed %d",
                 start.x_m, start.y_m, *target_m, target_yaw_deg, seed)
        return None


def build_sim_robot(config: OnboardConfig, world: World) -> SimRobot:
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
    faults = FaultInjector(clock)
    devices = faults.wrap(Devices("sim", clock, base, pantilt, camera))
    return SimRobot(world, devices, base, pantilt, camera, faults)
