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
[hardware.base]   # PioneerConfig (below); used when backend = "hardware"
port = "/dev/pioneer"   # a device path, a pyserial URL ("socket://127.0.0.1:8101") or "sim"
[hardware.pantilt] # PtuConfig
port = "/dev/ptu"       # or "sim"
[hardware.camera]  # UvcStereoConfig
device = "/dev/video0"  # or "sim"
calibration = "stereo.yaml"
```
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

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
class PioneerConfig:
    """``[hardware.base]``: where the Pioneer is and how the driver talks to it."""

    port: str = "sim"  # a device path, a pyserial URL ("socket://127.0.0.1:8101"), or "sim" for the simulator
    baud: int = field(default=9600, metadata=bounds(1200, 921600))  # ARCOS talks 9600 after power-up
    sync_reply_timeout_ms: int = field(default=1000, metadata=bounds(10, 10_000))  # ARIA waits 1 s per echo
    sync_attempts: int = field(default=4, metadata=bounds(1, 100))
    stale_session_wait_ms: int = field(default=500, metadata=bounds(0, 10_000))  # after CLOSE to an old session
    link_timeout_ms: int = field(default=1000, metadata=bounds(200, 60_000))  # no SIP this long: link down
    reconnect_period_ms: int = field(default=1000, metadata=bounds(50, 60_000))
    pulse_period_ms: int = field(default=500, metadata=bounds(50, 1900))  # idle keep-alive (the robot halts at 2 s)
    resend_period_ms: int = field(default=500, metadata=bounds(50, 1900))  # motion commands repeated, as ARIA does
    command_gap_ms: float = field(default=4.0, metadata=bounds(0.0, 50.0))  # ARCOS takes one command every 3-5 ms
    turn_tolerance_deg: float = field(default=1.0, metadata=bounds(0.1, 20.0))
    drive_tolerance_m: float = field(default=0.02, metadata=bounds(0.001, 0.5))
    motion_timeout_margin_s: float = field(default=5.0, metadata=bounds(0.5, 600.0))  # beyond the profile's time


@dataclass(frozen=True)
class PtuConfig:
    """``[hardware.pantilt]``; the slew speeds come from ``[pantilt]`` so the time model matches."""

    port: str = "sim"  # a device path or a pyserial URL (socket://HOST:PORT); "sim" = simulated
    baud: int = field(default=9600, metadata=bounds(1200, 115_200))  # the unit's power-up rate
    reply_timeout_s: float = field(default=0.5, metadata=bounds(0.01, 10.0))  # one command's answer
    startup_timeout_s: float = field(default=30.0, metadata=bounds(0.1, 120.0))  # self-calibration
    move_timeout_s: float = field(default=15.0, metadata=bounds(0.5, 120.0))  # beyond the slew the speeds give
    poll_s: float = field(default=0.05, metadata=bounds(0.001, 1.0))  # position polling during a look


@dataclass(frozen=True)
class UvcStereoConfig:
    """``[hardware.camera]``."""

    device: str = "sim"  # /dev/video0, a camera index, a video file or image sequence; "sim" = simulated
    calibration: str = "stereo.yaml"  # OpenCV YAML from calibrate-stereo
    width_px: int = field(default=1280, metadata=bounds(32, 8192))  # the side-by-side frame: both images
    height_px: int = field(default=480, metadata=bounds(16, 4096))
    fps: float = field(default=30.0, metadata=bounds(1.0, 240.0))
    stale_frames: int = field(default=2, metadata=bounds(0, 30))  # dropped before a capture: UVC queues frames
    swap_halves: bool = False  # True if the camera puts the right image in the left half


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
