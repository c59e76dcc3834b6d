"""Run one decoder against generated bad input and judge each outcome.

A :class:`FuzzTarget` is a decoder, the one error type it documents and a hypothesis strategy of
:class:`Case` s (valid inputs broken in one known place). A case fails when the decoder

- raises anything but the documented error (a crash the caller could not have handled),
- raises the documented error with a message that does not name the broken field, or
- accepts a case that must be refused (NaN, a wrong type, an unknown key...).

Unlike a test, :func:`run_target` does not stop at the first failure: it counts them and keeps a few
examples, so one command can report on every decoder. Both programs' fuzzers (``onboard.fuzz``,
``offboard.fuzz``) run their targets through it. Hypothesis is a test extra: call
:func:`require_hypothesis` first for a clear message when it is missing.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from typing import Any

INSTALL_HINT = ("fuzzing needs hypothesis, a test extra: install it with "
                "`.venv/bin/pip install -e '.[test]'` (or `pip install 'hypothesis>=6.100'`)")
EXAMPLES_KEPT = 5
_PROGRAM_RECURSION_LIMIT = sys.getrecursionlimit()  # as imported: hypothesis raises it while it runs
BATCH = 20  # cases per hypothesis example: its engine costs more per example than most decoders do


class MissingHypothesis(RuntimeError):
    """Hypothesis is not installed; the message says how to install it."""


def require_hypothesis() -> None:
    try:
        import hypothesis  # noqa: F401
    except ImportError:
        raise MissingHypothesis(INSTALL_HINT) from None


@dataclass(frozen=True)
class Case:
    """One input for a decoder and what must happen to it."""

    data: Any
    field: str | None  # the key the case broke, which the error must name; None: any refusal will do
    must_refuse: bool  # False for mutations that may still be valid (a number replaced by another)
    how: str  # the mutation, for the report
    exact: bool = True  # the error must name ``field`` itself, not just some part of its path


@dataclass(frozen=True)
class FuzzTarget:
    name: str
    cases: Callable[[], Any]  # () -> a hypothesis strategy of Case (built only once hypothesis is there)
    decode: Callable[[Any], Any]
    error: type[BaseException]


@dataclass
class FuzzReport:
    decoder: str
    cases: int = 0
    refused: int = 0  # the documented error, naming the field
    accepted: int = 0
    failures: int = 0
    seconds: float = 0.0
    examples: list[str] = field(default_factory=list)  # the first few failures

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def names_field(exc: BaseException, case: Case) -> bool:
    """Whether an error names what the case broke.

    Exact cases (a wrong type, NaN, a missing or unknown key) must name the field's path, or the
    list holding it (``room.size`` for ``room.size[1]``). Others (a value that clashes with another
    field) may name any part of the path (``obstacle`` for a moved ``obstacle[2].min``) or the
    other field (``robot.start`` when an obstacle moved onto the robot).
    """
    message = _GOT.sub("", str(exc))  # the offending value may hold every key of the input: not a name
    if case.field is None:
        return True
    if case.field in message or re.sub(r"\[\d+\]$", "", case.field) in message:
        return True
    if case.exact:
        return False
    parts = [p for p in re.split(r"[.\[\]]", case.field) if p and not p.isdigit()]
    return any(re.search(rf"\b{re.escape(p)}\b", message) for p in parts) or bool(named_key(exc))


def named_key(exc: BaseException) -> str:
    """The key an error names: its ``field`` attribute, or the ``key.path[i]:`` its message starts with."""
    field = getattr(exc, "field", None)
    if isinstance(field, str):
        return field
    match = _KEY_PREFIX.match(str(exc))
    return match.group(1) if match else ""


_GOT = re.compile(r" \(got .*\)$", re.DOTALL)  # how StructureError ends its message
_KEY_PREFIX = re.compile(r"^([A-Za-z_]\w*(?:\[\d+\])?(?:\.[A-Za-z_]\w*(?:\[\d+\])?)*): ")


@contextmanager
def _program_recursion_limit():
    """Python's usual recursion limit for the duration. Hypothesis raises the limit by thousands of
    frames while it runs, which hid a decoder's RecursionError on ~1000 nested arrays from this
    fuzzer; the agent, fuzzed live, raised it."""
    raised = sys.getrecursionlimit()
    sys.setrecursionlimit(_PROGRAM_RECURSION_LIMIT)
    try:
        yield
    finally:
        sys.setrecursionlimit(raised)


def judge(target: FuzzTarget, case: Case) -> tuple[str, str | None]:
    """``("refused" | "accepted" | "failed", what went wrong)`` for one case, decoded under the
    recursion limit a program runs with."""
    try:
        with _program_recursion_limit():
            target.decode(case.data)
    except target.error as exc:
        if names_field(exc, case):
            return "refused", None
        return "failed", f"{case.how}: the error does not name {case.field!r}: {exc}"
    except Exception as exc:  # noqa: BLE001 - any other exception is exactly what the fuzzer looks for
        return "failed", f"{case.how}: raised {type(exc).__name__}, not {target.error.__name__}: {exc}"
    if case.must_refuse:
        return "failed", f"{case.how}: accepted although it must be refused ({case.field})"
    return "accepted", None


def for_each_generated(strategy: Any, count: int, each: Callable[[Any], None]) -> None:
    """Call ``each`` on at least ``count`` values that hypothesis generates from ``strategy``
    (generation only, no shrinking), drawn ``BATCH`` at a time."""
    require_hypothesis()
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import strategies as st

    done = 0

    @settings(max_examples=-(-count // BATCH), deadline=None, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(st.lists(strategy, min_size=BATCH, max_size=BATCH))
    def run(batch: list) -> None:
        nonlocal done
        for value in batch:
            each(value)
        done += len(batch)

    while done < count:  # a strategy with few distinct values may stop early: go again
        run()


def run_target(target: FuzzTarget, cases: int) -> FuzzReport:
    """Run at least ``cases`` generated cases through ``target``; never stops at a failure."""
    report = FuzzReport(target.name)
    started = time.perf_counter()

    def run(case: Case) -> None:
        report.cases += 1
        outcome, problem = judge(target, case)
        report.refused += outcome == "refused"
        report.accepted += outcome == "accepted"
        if problem is not None:
            report.failures += 1
            if len(report.examples) < EXAMPLES_KEPT:
                report.examples.append(f"{problem} [input: {_shown(case.data)}]")

    for_each_generated(target.cases(), cases, run)
    report.seconds = round(time.perf_counter() - started, 2)
    return report


def _shown(data: Any) -> str:
    text = repr(data)
    return text if len(text) <= 300 else text[:297] + "..."


def run_targets(targets: list[FuzzTarget], cases: int, only: tuple[str, ...] = ()) -> list[FuzzReport]:
    """Run every target (or those whose name contains one of ``only``), ``cases`` cases each."""
    return [run_target(t, cases) for t in targets if not only or any(o in t.name for o in only)]


def summary(reports: list[FuzzReport], cases: int) -> dict[str, Any]:
    """The JSON object of a fuzz run: per decoder, and the failures in all."""
    return {"cases_per_decoder": cases, "decoders": [r.to_json() for r in reports],
            "failures": sum(r.failures for r in reports),
            "short": [r.decoder for r in reports if r.cases < cases]}


def table(reports: list[FuzzReport]) -> str:
    """A readable report: one line per decoder, then the examples of each failure."""
    lines = [f"{'decoder':32} {'cases':>7} {'refused':>8} {'accepted':>8} {'failures':>8} {'s':>7}"]
    for r in reports:
        lines.append(f"{r.decoder:32} {r.cases:7} {r.refused:8} {r.accepted:8} {r.failures:8} {r.seconds:7.1f}")
        lines += [f"    {example}" for example in r.examples]
    return "\n".join(lines)
