"""The emulated robot of ``syt-onboard emulate``: a Pioneer and a PTU-D46 at the byte level on
pseudo-terminals, over one simulated world, plus the truth link a simulated camera renders from.

The Pioneer emulator drives a :class:`SimBase` in the world (walls and furniture stall it, its
odometry drifts as the simulator's does); the PTU emulator slews its own head. The truth link
(``onboard.emulators.truth``) serves the base's true pose and the head's true angles.
"""

from __future__ import annotations

import contextlib
import logging
import tempfile
from pathlib import Path

from onboard.config import OnboardConfig
from onboard.emulators.pioneer import PioneerEmulator, PioneerServerState
from onboard.emulators.ptu import PtuEmulator
from onboard.emulators.truth import Truth, TruthServer, WorldPlacement
from onboard.sim.base import SimBase
from onboard.sim.clock import SimClock
from shared.world import World

log = logging.getLogger(__name__)


class EmulatedRobot:
    """Starts on ``__enter__``, stops on ``__exit__``; ``ports()`` is what ``emulate`` announces."""

    def __init__(self, config: OnboardConfig, world: World, world_file: str | Path):
        self._placement = WorldPlacement.of(world, world_file)
        self.base = SimBase(world, config.base, SimClock(), config.sim.odometry_noise, seed=config.sim.seed,
                            step_s=config.sim.step_s)
        self.pioneer = PioneerEmulator(PioneerServerState(self.base))
        self.ptu = PtuEmulator(slew=config.pantilt)
        self._stack = contextlib.ExitStack()
        self.truth_path = ""

    def truth(self) -> Truth:
        head = self.ptu.reading()
        return Truth(self.base.true_pose, head.pan_rad, head.tilt_rad, head.moving)

    def ports(self) -> dict[str, str]:
        return {"base": self.pioneer.path, "pantilt": self.ptu.device_path, "truth": self.truth_path}

    def __enter__(self) -> EmulatedRobot:
        with contextlib.ExitStack() as stack:
            folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="syt-emulate-"))
            self.truth_path = str(Path(folder) / "truth.sock")
            stack.enter_context(self.pioneer)
            stack.enter_context(self.ptu)
            stack.callback(TruthServer(self.truth_path, self._placement, self.truth).start().close)
            self._stack = stack.pop_all()
        log.info("emulated robot in %s: %s", self._placement.world, self.ports())
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()
