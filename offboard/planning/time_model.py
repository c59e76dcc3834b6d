"""t(f): how long an action takes on the robot (report §3.1), from the limits the robot reports.

An action moves the sensor (travel along the navigation path, turning, slewing the pan-tilt unit),
takes an image, and analyses it. Travel is costed along the path the navigator would drive, not
the straight line, at the rate the navigator is measured to drive it: it moves in short steps from
rest to rest and looks ahead before each, so a metre takes several times a straight drive's time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shared.limits import BaseLimits, CameraTiming, PanTiltLimits


@dataclass(frozen=True)
class LookPlan:
    """How to point the camera at a world azimuth from the current heading."""

    base_turn_rad: float  # 0 unless the pan-tilt unit cannot reach the azimuth by itself
    pan_rad: float
    tilt_rad: float
    time_s: float  # turning + slewing + capture + processing


@dataclass(frozen=True)
class TimeModel:
    base: BaseLimits
    pantilt: PanTiltLimits
    camera: CameraTiming
    processing_s: float = 0.5  # stereo, detection, map and belief update, planning (measured at run time)
    drive_s_per_m: float = 0.0  # time per metre of a move (measured at run time); 0: one straight drive

    def __post_init__(self) -> None:
        for name in ("processing_s", "drive_s_per_m"):  # negative would make a look or a metre take less than nothing
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite time of at least 0 s, not {value}")

    @property
    def image_s(self) -> float:
        return self.camera.capture_s + self.processing_s

    def look(self, heading_rad: float, pan_rad: float, tilt_rad: float, azimuth_rad: float,
             target_tilt_rad: float) -> LookPlan:
        """Point at ``azimuth_rad`` (world) and ``target_tilt_rad``, turning the base only if needed."""
        pan, turn, time_s = self._pointing(heading_rad, pan_rad, tilt_rad, azimuth_rad, target_tilt_rad)
        return LookPlan(float(turn), float(pan), target_tilt_rad, float(time_s))

    def look_times_s(self, heading_rad, pan_rad: float, tilt_rad: float, azimuths_rad: np.ndarray,
                     tilts_rad: np.ndarray) -> np.ndarray:
        """:meth:`look`'s time for every setting at once; ``heading_rad`` may be an array that
        broadcasts against the settings (one heading per candidate position, say)."""
        return self._pointing(heading_rad, pan_rad, tilt_rad, azimuths_rad, tilts_rad)[2]

    def _pointing(self, heading_rad, pan_rad: float, tilt_rad: float, azimuths_rad, tilts_rad):
        """The pan toward each azimuth (within the unit's limits), the base turn that makes up the rest,
        and the look's time: turning, slewing from (``pan_rad``, ``tilt_rad``), the image."""
        wanted = _wrapped(np.asarray(azimuths_rad, float) - np.asarray(heading_rad, float))
        pan = np.clip(wanted, math.radians(self.pantilt.pan_min_deg), math.radians(self.pantilt.pan_max_deg))
        turn = _wrapped(wanted - pan)
        slew = self.pantilt.slew_time_s(np.degrees(pan - pan_rad), np.degrees(np.asarray(tilts_rad) - tilt_rad))
        return pan, turn, self.base.turn_time_s(turn) + slew + self.image_s

    def travel_s(self, path_length_m, turn_rad):
        """Drive a path of this length after turning towards it; inf for no path (numbers or arrays)."""
        length = np.asarray(path_length_m, np.float64)
        if np.any(bad := np.isnan(length) | (length < 0)):
            raise ValueError(f"path_length_m must be at least 0 m (inf: no path), not {length[bad].flat[0]}")
        reachable = np.isfinite(length)
        length = np.where(reachable, length, 0.0)
        drive = length * self.drive_s_per_m if self.drive_s_per_m > 0 else self.base.drive_time_s(length)
        t = self.base.turn_time_s(turn_rad) + drive
        t = np.where(reachable, t, np.inf)
        return float(t) if t.ndim == 0 else t


def _wrapped(angle_rad: np.ndarray) -> np.ndarray:
    """Angles wrapped to (-pi, pi]."""
    return np.angle(np.exp(1j * angle_rad))
