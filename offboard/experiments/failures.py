"""Why each failed run failed, so that a failure is read before it is averaged: an oracle that fails
is a broken yardstick (issue 12), and a search that fails for a reason outside the planner says
nothing about the planner.

A failed run is put down to one cause:

- **not found**: the search stopped without the target (its status says how: ``exhausted``,
  ``max_actions``, a budget, a crash);
- **localisation**: found, but at its last look the error of the pose the robot believed it had
  (against the simulator's truth in ``looks.jsonl``) alone moved the target more than
  :data:`~offboard.experiments.calibration.LOCALISATION_FAR_M` (:meth:`Look.shift_at`): position and
  heading both, since 5° of heading moves a target 4 m away by 0.35 m;
- **estimate**: found, the pose right enough, and the estimate still outside the success radius;
- **pose unchecked**: found, but whether the pose was right enough cannot be told: no look logged the
  simulator's truth, or the run's target is not ``x,y,z,yaw`` (the report names those runs).
"""

from __future__ import annotations

from dataclasses import dataclass

from offboard.experiments.calibration import LOCALISATION_FAR_M, Look, cell
from offboard.experiments.world_facts import parse_placement

CAUSES = ("not found", "localisation", "estimate", "pose unchecked")
Groups = list[tuple[str, list[dict]]]  # (variant name, its rows), as the report groups runs


@dataclass(frozen=True)
class Failure:
    variant: str
    row: dict
    cause: str  # one of CAUSES
    pose_error_m: float | None  # at the run's last look that logged the truth
    target_shift_m: float | None  # how far that look's pose error alone moved the target
    target_error: str | None = None  # why the shift is unknown though a look logged the truth: a malformed target


def last_true_look(looks: list[Look]) -> Look | None:
    """The last look that logged the simulator's truth beside the believed pose."""
    return next((look for look in reversed(looks) if look.truth is not None), None)


def failure(variant: str, row: dict, last: Look | None) -> Failure:
    shift, target_error = _shift(row, last)
    if not row["found"]:
        why = "not found"
    elif shift is None:
        why = "pose unchecked"
    else:
        why = "localisation" if shift > LOCALISATION_FAR_M else "estimate"
    return Failure(variant, row, why, None if last is None else last.pose_error_m, shift, target_error)


def _shift(row: dict, last: Look | None) -> tuple[float | None, str | None]:
    """How far ``last``'s pose error moved the row's target, or None and, for a malformed target, why:
    one such run must not keep the rest of the report from being written."""
    if last is None:
        return None, None
    try:
        return last.shift_at(parse_placement(row["target"])[:2]), None
    except ValueError as exc:
        return None, str(exc)


def failures(groups: Groups, last_looks: dict[str, Look | None]) -> list[Failure]:
    """Every failed run of ``groups`` with its cause; ``last_looks``: :func:`last_true_look` by row key."""
    return [failure(name, r, last_looks.get(r["key"])) for name, rows in groups for r in rows if not r["success"]]


def failures_md(groups: Groups, last_looks: dict[str, Look | None]) -> list[str]:
    """The report's section: failures per variant and cause, then every failed run."""
    found = failures(groups, last_looks)
    lines = ["## Failures", "",
             "Each failed run's cause: **not found** (the search stopped without the target; its status says how), "
             "**localisation** (found, but at its last look the error of the pose the robot believed it had, position "
             f"and heading, alone moved the target more than {LOCALISATION_FAR_M:g} m), **estimate** (found, the pose "
             "right enough, the estimate still outside the success radius) or **pose unchecked** (found, but no look "
             "logged the simulator's pose, or the run's target is malformed, so the pose's part cannot be told).", ""]
    if not found:
        return lines + ["No run failed.", ""]
    lines += ["| Variant | Runs | Failed | " + " | ".join(c.capitalize() for c in CAUSES) + " |",
              "|---" * (3 + len(CAUSES)) + "|"]
    for name, rows in groups:
        mine = [f.cause for f in found if f.variant == name]
        lines.append(f"| {name} | {len(rows)} | {len(mine)} | " + " | ".join(str(mine.count(c)) for c in CAUSES) + " |")
    lines += ["", "| Variant | World | Start | Target | Seed | Cause | Status | Looks | Distance (m) | Estimate off (m) "
              "| Pose off at the last look (m) | Target moved by it (m) |", "|---" * 12 + "|"]
    for f in found:
        r = f.row
        lines.append(f"| {f.variant} | {r['world']} | {r['start']} | {r['target']} | {cell(r['seed'], 0)} | {f.cause} "
                     f"| {r['status']} | {cell(r['actions'], 0)} | {cell(r['distance_m'])} "
                     f"| {cell(r['estimate_error_m'])} | {cell(f.pose_error_m)} | {cell(f.target_shift_m)} |")
    malformed = [f"- {f.row['key']}: {f.target_error}" for f in found if f.target_error]
    if malformed:
        lines += ["", "Runs whose target is malformed, so how far the pose error moved it is unknown:", ""] + malformed
    return lines + [""]
