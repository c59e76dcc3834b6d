"""A search's checkpoint: what it takes to carry on after the planner's process dies (issue 14).

After every action :class:`Checkpointer` writes ``checkpoint.syt`` into the search's out folder,
atomically (a temporary file in the same folder, fsync, ``os.replace``, fsync of the folder): a
crash leaves the previous checkpoint or the new one, never part of one. It holds

- the belief, exactly (per-cube masses, the coarse copy, the cubes seen empty, c_out, the scale, P[F]),
- the occupancy grid (log-odds and which cubes were observed),
- the pose tracker (estimate, covariance and the odometry-to-world offset),
- the search's history (:class:`SearchState`: looks, taken settings, unreachable goals, positions,
  trail, planning times, motion and processing totals, estimate), the robot clock at the start, the
  planning time not yet booked, the planner's measured processing time per look, the camera poses
  of every image searched, looks and glances (so that no view is searched twice), and what each dynamic prior
  has applied so far,
- the wall time so far, the search configuration, the request and the transport, so that
  ``syt-offboard search --resume DIR`` needs no other flag.

The file: ``MAGIC``, the JSON header's length (little-endian u64), the JSON header (the plain state
and where each array lies), then the arrays, each 64-byte aligned. Floats go through JSON as Python
writes them (shortest repr), which reads back to the same bits. The belief (29 MB of float32 at
5 cm with 8 facings) and the log-odds are coded by :mod:`offboard.search.repeat_codec`: exact, and
a few MB after a few looks.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from offboard.search import repeat_codec
from offboard.search.loop import Search, SearchConfig, SearchState
from offboard.search.run import LookPrior, SearchRequest
from offboard.search.top_view import LookTrace
from shared.geometry import RigidTransform
from shared.strict import StructureError, build
from shared.transport import TransportConfig

log = logging.getLogger(__name__)

FILE_NAME = "checkpoint.syt"
MAGIC = b"SYTCKPT\x00"
VERSION = 5  # 2: the belief's blocked facings; 3: the dynamic priors' memory; 4: no retaken settings;
# 5: the views of looks too, not only of glances
ALIGN = 64
HEADER_KEYS = ("request", "transport", "config", "wall_time_s", "search", "belief", "coded", "grid_shape", "arrays")


class CheckpointError(StructureError):
    """A checkpoint that cannot be read back or does not fit the search it is given to."""


@dataclass(frozen=True)
class Checkpoint:
    """A checkpoint as read: the plain header and its arrays, plus what the header describes."""

    path: Path
    header: dict
    arrays: dict[str, np.ndarray]

    @property
    def request(self) -> SearchRequest:
        """The request, with ``out_dir`` the checkpoint's folder (wherever it was moved)."""
        with _damaged(self.path, "request"):
            return dataclasses.replace(request_from_plain(self.header["request"]), out_dir=self.path.parent)

    @property
    def transport(self) -> TransportConfig:
        with _damaged(self.path, "transport"):
            plain = dict(self.header["transport"])
            zenoh_config = plain.pop("zenoh_config")
            return TransportConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in plain.items()},
                                   zenoh_config=None if zenoh_config is None else Path(zenoh_config))

    @property
    def config(self) -> SearchConfig:
        try:
            return build(SearchConfig, self.header["config"], CheckpointError, "config")
        except CheckpointError as exc:
            raise CheckpointError(f"{self.path}: {exc.field}", exc.value, exc.problem) from None

    @property
    def wall_time_s(self) -> float:
        with _damaged(self.path, "wall_time_s"):
            return float(self.header["wall_time_s"])

    @property
    def actions(self) -> int:
        with _damaged(self.path, "search.state.actions"):
            return int(self.header["search"]["state"]["actions"])


@contextlib.contextmanager
def _damaged(path: Path, part: str):
    """A checkpoint whose ``part`` is not as this syt writes it (hand-edited, or from another
    version) raises whatever Python raises on the first odd field: name the file and the part."""
    try:
        yield
    except CheckpointError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        problem = f"missing {exc}" if isinstance(exc, KeyError) else f"{type(exc).__name__}: {exc}"
        raise CheckpointError(f"{path}: {part}", None, f"damaged or from another version ({problem})") from None


class Checkpointer:
    """Writes a search's checkpoint after every action: give it to the search as ``on_action``."""

    def __init__(self, out_dir: Path, request: SearchRequest, transport: TransportConfig,
                 wall_before_s: float = 0.0):
        self.path = out_dir / FILE_NAME
        for stale in out_dir.glob(f".{FILE_NAME}.*.tmp"):  # a write cut short by a crash
            stale.unlink()
        self._fixed = {"request": request_plain(request), "transport": transport_plain(transport)}
        self._started = time.monotonic()
        self._wall_before_s = wall_before_s
        self.write_ms: list[float] = []
        self.size_bytes = 0
        repeat_codec.encode(np.zeros((2, 2), np.float32))  # compile (or load) the kernels before the first action

    def __call__(self, search: Search) -> None:
        started = time.perf_counter()
        wall_s = self._wall_before_s + time.monotonic() - self._started
        header, arrays = capture(search)
        header.update(self._fixed, config=dataclasses.asdict(search.config), wall_time_s=wall_s)
        try:
            self.size_bytes = write_file(self.path, header, arrays)
        except OSError as exc:  # a full disk must not end the search: the previous checkpoint stays
            log.error("checkpoint after action %d not written: %s", search.state.actions, exc)
            return
        self.write_ms.append((time.perf_counter() - started) * 1000.0)
        log.info("checkpoint after action %d: %.1f MB in %.0f ms", search.state.actions, self.size_bytes / 1e6,
                 self.write_ms[-1])


def attach(search: Search, request: SearchRequest, transport: TransportConfig, resume: Checkpoint | None) -> None:
    """Restore ``search`` from ``resume`` (if given) and, if the request asks for it, checkpoint it
    after every action from now on."""
    if resume is not None:
        restore(search, resume)
    if request.checkpoint:
        search.on_action = Checkpointer(request.out_dir, request, transport,
                                        0.0 if resume is None else resume.wall_time_s)


# --- the search's state -----------------------------------------------------------------------------

def capture(search: Search) -> tuple[dict, dict[str, np.ndarray]]:
    """The search's state: a plain header part and the arrays (not copied: write them before the
    search goes on)."""
    header, arrays = encode_maps(search.belief.state(), search.occupancy.log_odds, search.occupancy.observed)
    header["search"] = {
        "state": state_plain(search.state),
        "clock_start_s": float(search._clock_start_s),
        "robot_id": search.info.robot_id,
        "robot_clock_s": float(search._clock_start_s + search.robot_time_s()),  # the robot's own clock, now
        "pending_processing_s": float(search._pending_processing_s),
        "planner_processing_s": float(search.planner.time_model.processing_s),
        "tracker": search.tracker.state(),
        "seen": [_plain(np.concatenate([view.rotation.ravel(), view.translation])) for view in search._seen],
        "priors": {},
    }
    for name, prior in _look_priors(search):  # what each dynamic prior has applied so far
        memory = repeat_codec.encode(prior.source.memory())
        header["search"]["priors"][name] = [list(memory.shape), memory.dtype]
        arrays.update(_coded(name, memory))
    return header, arrays


def _look_priors(search: Search) -> list[tuple[str, LookPrior]]:
    return [(f"prior.{i}", prior) for i, prior in enumerate(search.dynamic_priors) if isinstance(prior, LookPrior)]


def encode_maps(belief: dict, log_odds: np.ndarray, observed: np.ndarray) -> tuple[dict, dict[str, np.ndarray]]:
    """The belief's :meth:`~TargetBelief.state` and the occupancy grid as a header part and arrays."""
    mass = repeat_codec.encode(belief["mass"])
    odds = repeat_codec.encode(log_odds)
    header = {"belief": {k: float(belief[k]) for k in ("outside", "scale", "stored_total", "success_prob")},
              "coded": {"belief.mass": [list(mass.shape), mass.dtype], "occupancy.log_odds": [list(odds.shape), odds.dtype]},
              "grid_shape": list(observed.shape)}
    arrays = {**_coded("belief.mass", mass), "belief.coarse": belief["coarse"],
              "belief.seen_empty": np.packbits(belief["seen_empty"]),
              "belief.facing_blocked": np.packbits(belief["facing_blocked"]), **_coded("occupancy.log_odds", odds),
              "occupancy.observed": np.packbits(observed)}
    return header, arrays


def _coded(name: str, encoded: repeat_codec.Encoded) -> dict[str, np.ndarray]:
    arrays = {f"{name}.flags": encoded.flags, f"{name}.values": encoded.values}
    if encoded.palette is not None:
        arrays[f"{name}.palette"] = encoded.palette
    return arrays


def _decoded(checkpoint: Checkpoint, name: str, shape: list[int], dtype: str) -> np.ndarray:
    """The array that :func:`_coded` stored under ``name``."""
    a = checkpoint.arrays
    return repeat_codec.decode(repeat_codec.Encoded(tuple(shape), dtype, a[f"{name}.flags"], a[f"{name}.values"],
                                                    a.get(f"{name}.palette")))


def decode_maps(checkpoint: Checkpoint) -> tuple[dict, np.ndarray, np.ndarray]:
    """The belief state, log-odds and observed mask that :func:`encode_maps` was given."""
    h, a = checkpoint.header, checkpoint.arrays
    with _damaged(checkpoint.path, "maps"):
        mass, odds = (_decoded(checkpoint, name, shape, dtype) for name, (shape, dtype) in h["coded"].items())
        shape = tuple(h["grid_shape"])
        seen_empty, observed = (np.unpackbits(a[name], count=int(np.prod(shape))).astype(bool).reshape(shape)
                                for name in ("belief.seen_empty", "occupancy.observed"))
        blocked = np.unpackbits(a["belief.facing_blocked"], count=mass.size).astype(bool).reshape(mass.shape)
        return ({**h["belief"], "mass": mass, "coarse": a["belief.coarse"], "seen_empty": seen_empty,
                 "facing_blocked": blocked}, odds, observed)


def restore(search: Search, checkpoint: Checkpoint) -> None:
    """Put a freshly built search (same request, same robot) back where the checkpoint left it."""
    if search.config != checkpoint.config:
        raise CheckpointError(str(checkpoint.path), None, "the search's configuration is not the checkpoint's")
    belief, odds, observed = decode_maps(checkpoint)
    with _damaged(checkpoint.path, "search"):  # read all of it before the search is changed
        part = checkpoint.header["search"]
        seen = [_view(g) for g in part["seen"]]
        state = state_from_plain(part["state"])
        clock_start_s, pending_s, planner_s = (float(part[k]) for k in ("clock_start_s", "pending_processing_s",
                                                                         "planner_processing_s"))
        _check_same_robot(search, checkpoint, part["robot_id"], float(part["robot_clock_s"]))
        search.belief.restore(belief)
        with search.occupancy.edit() as (log_odds, was_observed):
            log_odds[:], was_observed[:] = odds, observed
        search.tracker.restore(part["tracker"])
    search.state = state
    search._clock_start_s = clock_start_s
    search._pending_processing_s = pending_s
    search.planner.set_processing_s(planner_s)
    search._seen = seen
    if search.state.widened:
        search.planner.widen()
    search.measure_driving()
    _restore_priors(search, checkpoint)
    log.info("resumed after action %d (P[F] = %.3f)", search.state.actions, search.belief.success_prob)


def _check_same_robot(search: Search, checkpoint: Checkpoint, robot_id: str, robot_clock_s: float) -> None:
    """The map, the belief and the pose offset are in the odometry frame of the robot that made
    them, as it ran then: another robot, or the same one restarted (its clock and odometry begin
    afresh), would read them in a frame they are not in."""
    if search.info.robot_id != robot_id:
        raise CheckpointError(f"{checkpoint.path}: robot", search.info.robot_id,
                              f"the checkpoint is of robot {robot_id!r}")
    now_s = search._clock_start_s  # the robot's clock as the resumed search started
    if now_s < robot_clock_s:
        raise CheckpointError(f"{checkpoint.path}: robot", now_s,
                              f"its clock is behind the checkpoint's {robot_clock_s:.1f} s: the robot's agent "
                              "restarted, and its odometry with it, so the saved map and pose no longer line up; "
                              "start a new search")


def _view(plain: list[float]) -> RigidTransform:
    """A glance's camera pose from its rotation (row by row) and translation."""
    return RigidTransform(np.array(plain[:9], np.float64).reshape(3, 3), np.array(plain[9:], np.float64))


def _restore_priors(search: Search, checkpoint: Checkpoint) -> None:
    saved = checkpoint.header["search"].get("priors", {})
    for name, prior in _look_priors(search):
        if name not in saved:
            raise CheckpointError(f"{checkpoint.path}: search.priors.{name}", None,
                                  "the checkpoint has no memory for this search's dynamic prior")
        with _damaged(checkpoint.path, f"search.priors.{name}"):
            prior.source.restore(_decoded(checkpoint, name, *saved[name]))


_STATE_FIELDS = {
    "positions": lambda v: [tuple(p) for p in v],
    "trail": lambda v: [tuple(p) for p in v],
    "unreachable": lambda v: [tuple(p) for p in v],
    "looks": lambda v: [LookTrace(**look) for look in v],
    "estimate_m": lambda v: None if v is None else np.array(v, np.float64),
    "views": lambda v: [tuple(p) for p in v],
    "taken": set,
}


def state_plain(state: SearchState) -> dict:
    return {f.name: _plain(getattr(state, f.name)) for f in dataclasses.fields(SearchState)}


def state_from_plain(plain: dict) -> SearchState:
    known = {f.name for f in dataclasses.fields(SearchState)}
    unknown = sorted(set(plain) - known)
    if unknown:
        raise CheckpointError(f"search.state.{unknown[0]}", plain[unknown[0]], "unknown field of SearchState")
    return SearchState(**{k: _STATE_FIELDS.get(k, lambda v: v)(v) for k, v in plain.items()})


def request_plain(request: SearchRequest) -> dict:
    """The request with every file made absolute, so that a resume works from any folder."""
    def absolute(spec: str) -> str:
        name, _, path = spec.partition("=")
        return f"{name}={Path(path).resolve()}"

    return {**_plain(dataclasses.asdict(request)), "pictures": [str(p.resolve()) for p in request.pictures],
            "detectability": [absolute(s) for s in request.detectability],
            "config_path": None if request.config_path is None else str(request.config_path.resolve()),
            "out_dir": str(request.out_dir.resolve())}


def request_from_plain(plain: dict) -> SearchRequest:
    paths = {"pictures": lambda v: tuple(Path(p) for p in v), "out_dir": Path,
             "config_path": lambda v: None if v is None else Path(v)}
    known = {f.name for f in dataclasses.fields(SearchRequest)}
    unknown = sorted(set(plain) - known)
    if unknown:
        raise CheckpointError(f"request.{unknown[0]}", plain[unknown[0]], "unknown field of SearchRequest")
    return SearchRequest(**{k: paths[k](v) if k in paths else tuple(v) if isinstance(v, list) else v
                            for k, v in plain.items()})


def transport_plain(transport: TransportConfig) -> dict:
    return _plain(dataclasses.asdict(transport))


def _plain(value: Any) -> Any:
    """JSON-ready: numpy scalars and arrays, tuples, sets, paths and dataclasses to their plain kin."""
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (set, frozenset)):
        return sorted(_plain(v) for v in value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


# --- the file -----------------------------------------------------------------------------------------

def write_file(path: Path, header: dict, arrays: dict[str, np.ndarray]) -> int:
    """Write atomically; returns the file's size in bytes."""
    table, offset = {}, 0
    for name, array in arrays.items():
        offset = _aligned(offset)
        table[name] = {"dtype": array.dtype.str, "shape": list(array.shape), "offset": offset}
        offset += array.nbytes
    head = json.dumps({"version": VERSION, **header, "arrays": table}).encode()
    start = _aligned(len(MAGIC) + 8 + len(head))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(MAGIC + struct.pack("<Q", len(head)) + head)
            for name, array in arrays.items():
                f.seek(start + table[name]["offset"])
                f.write(np.ascontiguousarray(array).data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    folder = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(folder)  # the rename itself survives a power cut
    finally:
        os.close(folder)
    return start + offset


def read(folder: Path) -> Checkpoint:
    """The checkpoint in ``folder`` (or at that path); :class:`CheckpointError` naming what is wrong."""
    path = folder / FILE_NAME if folder.is_dir() else folder
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CheckpointError(str(path), None, f"cannot read the checkpoint: {exc.strerror}") from None
    if data[:len(MAGIC)] != MAGIC or len(data) < len(MAGIC) + 8:
        raise CheckpointError(str(path), data[:len(MAGIC)], "not a syt checkpoint")
    (length,) = struct.unpack_from("<Q", data, len(MAGIC))
    try:
        header = json.loads(data[len(MAGIC) + 8:len(MAGIC) + 8 + length])
    except ValueError as exc:
        raise CheckpointError(str(path), None, f"damaged header: {exc}") from None
    if not isinstance(header, dict) or header.get("version") != VERSION:
        raise CheckpointError(f"{path}: version", header.get("version") if isinstance(header, dict) else header,
                              f"this syt reads version {VERSION}")
    missing = [key for key in HEADER_KEYS if key not in header]
    if missing:
        raise CheckpointError(f"{path}: {missing[0]}", None, "missing from the checkpoint's header")
    start = _aligned(len(MAGIC) + 8 + length)
    arrays = {}
    with _damaged(path, "arrays"):
        listed = dict(header.pop("arrays"))
    for name, entry in listed.items():
        with _damaged(path, f"arrays.{name}"):
            dtype, shape = np.dtype(entry["dtype"]), tuple(entry["shape"])
            count = int(np.prod(shape, dtype=np.int64))
            begin = start + entry["offset"]
            if begin + count * dtype.itemsize > len(data):
                raise CheckpointError(f"{path}: {name}", len(data), "the file ends before this array")
            arrays[name] = np.frombuffer(data, dtype, count, begin).reshape(shape)
    return Checkpoint(path, header, arrays)


def _aligned(offset: int) -> int:
    return -(-offset // ALIGN) * ALIGN
