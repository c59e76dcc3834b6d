"""The onboard agent's configuration (TOML, validated at load; every default runs).

```toml
backend = "sim"
watchdog_ms = 800
[base]            # shared.limits.BaseLimits
max_speed_m_s = 1.2
[pantilt]         # shared.limits.PanTiltLimits
[camera]
hfov_deg = 66.0
[sim]
world = "paper-lab"
realtime = false
[sim.odometry_noise]
distance_frac = 0.02
[hardware.base]   # onboard.hardware.pioneer.PioneerConfig; used when backend = "hardware"
port = "/dev/pioneer"   # a device path, a pyserial URL ("socket://127.0.0.1:8101") or "sim"
[hardware.pantilt] # onboard.hardware.ptu.PtuConfig
port = "/dev/ptu"       # or "sim"
[hardware.camera]  # onboard.hardware.uvc_camera.UvcStereoConfig
device = "/dev/video0"  # or "sim"
calibration = "stereo.yaml"
```
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from onboard.hardware.pioneer import PioneerConfig
from onboard.hardware.ptu import PtuConfig
from onboard.hardware.uvc_camera import UvcStereoConfig
from shared.geometry import HeadMount, Intrinsics
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits
from shared.messages import HEARTBEAT_PERIOD_S
from shared.strict import bounds


@dataclass(frozen=True)
class CameraConfig:
    """A Bumblebee2 BB2-03S2 with 3.8 mm lenses, rectified to 640×480."""

    width_px: int = field(default=640, metadata=bounds(16, 4096))
    height_px: int = field(default=480, metadata=bounds(16, 4096))
    hfov_deg: float = field(default=66.0, metadata=bounds(10.0, 150.0))
    baseline_m: float = field(default=0.12, metadata=bounds(0.01, 1.0))
    head_height_m: float = field(default=1.2, metadata=bounds(0.1, 3.0))  # tilt axis above the floor
    head_forward_m: float = field(default=0.0, metadata=bounds(-1.0, 1.0))  # tilt axis ahead of centre

    def intrinsics(self) -> Intrinsics:
        return Intrinsics.from_fov(self.width_px, self.height_px, self.hfov_deg)

    def mount(self) -> HeadMount:
        return HeadMount(self.head_height_m, self.head_forward_m, self.baseline_m)


@dataclass(frozen=True)
class OdometryNoise:
    """Standard deviations of the odometry errors, drawn afresh for every motion (a real base's
    wheel-diameter and slip errors are systematic over one move, not white noise per tick)."""

    distance_frac: float = field(default=0.02, metadata=bounds(0.0, 0.5))  # scale error of distance
    turn_frac: float = field(default=0.02, metadata=bounds(0.0, 0.5))  # scale error of rotation
    drift_deg_per_m: float = field(default=1.0, metadata=bounds(0.0, 45.0))  # heading drift driving


@dataclass(frozen=True)
class SimConfig:
    world: str = "paper-lab"  # a bundled world name or a world file path
    realtime: bool = False  # pace the simulated clock like the real robot
    seed: int = field(default=0, metadata=bounds(0, 2**63 - 1))  # odometry noise (numpy takes no negative seed)
    step_s: float = field(default=0.02, metadata=bounds(1e-3, 0.5))  # physics step of robot time
    odometry_noise: OdometryNoise = OdometryNoise()


@dataclass(frozen=True)
class HardwareConfig:
    """``[hardware]``: the serial and camera devices of ``backend = "hardware"``. A device whose port
    (or camera device) is ``"sim"`` is simulated in ``[sim]``'s world, so a robot with only a real
    base can run; the defaults simulate all three."""

    base: PioneerConfig = PioneerConfig()
    pantilt: PtuConfig = PtuConfig()
    camera: UvcStereoConfig = UvcStereoConfig()
    # The Unix socket ``syt-onboard emulate`` announces as "truth": simulated devices then render the
    # emulated robot's world from its true pose and head angles instead of the agent's own readings.
    truth: str = ""

    def __post_init__(self) -> None:
        for key, value in (("base.port", self.base.port), ("pantilt.port", self.pantilt.port),
                           ("camera.device", self.camera.device)):
            if not value.strip():
                raise ValueError(f"hardware.{key} is empty: give a device path, a URL or \"sim\"")


@dataclass(frozen=True)
class OnboardConfig:
    backend: Literal["sim", "hardware"] = "sim"  # hardware: [hardware] below
    # stop if the planner is silent this long (4 heartbeats); shorter than 3, one late beat would stop every motion
    watchdog_ms: int = field(default=800, metadata=bounds(round(3000 * HEARTBEAT_PERIOD_S), 60_000))
    publish_hz: float = field(default=10.0, metadata=bounds(0.1, 200.0))  # odometry and pan/tilt
    base: BaseLimits = BaseLimits()
    pantilt: PanTiltLimits = PanTiltLimits()
    camera: CameraConfig = CameraConfig()
    timing: CameraTiming = CameraTiming()
    sim: SimConfig = SimConfig()  # the world of the simulator, and of hardware devices set to "sim"
    hardware: HardwareConfig = HardwareConfig()
