"""``syt-offboard compile`` and ``syt-onboard compile`` (``make`` runs both after installing) call every
numba kernel of their side, so that numba's on-disk cache holds them all before a search starts.
Each runs in a fresh process here, which then reports the kernels it called: a kernel numba has
compiled or loaded for some argument types has a signature."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# run a compile command's function, then name every kernel of PACKAGE (module, function) it called
SCRIPT = """
import importlib, json, sys
package, kernels = sys.argv[1], json.loads(sys.argv[2])
if package == "offboard":
    from offboard.kernel_cache import compile_kernels
    compile_kernels()
else:
    from onboard.cli import run_compile
    run_compile([])
modules = {m: importlib.import_module(m) for m, _ in kernels}
print(json.dumps([[m, f] for m, f in kernels if getattr(modules[m], f).signatures]))
"""


def _kernels(package: str) -> dict[tuple[str, str], set[tuple[str, str]]]:
    """(module, function) of every ``numba.njit`` function of ``package`` that numba caches on its
    own (not those inlined into their callers, ``inline="always"``), each with the kernels of its
    module it calls."""
    found = {}
    for path in (ROOT / package).rglob("*.py"):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        kernels = [node for node in ast.walk(ast.parse(path.read_text()))
                   if isinstance(node, ast.FunctionDef) and any(_is_cached_njit(d) for d in node.decorator_list)]
        names = {node.name for node in kernels}
        for node in kernels:
            calls = {c.func.id for c in ast.walk(node) if isinstance(c, ast.Call) and isinstance(c.func, ast.Name)}
            found[(module, node.name)] = {(module, name) for name in calls & names}
    return found


def _reached(called: set, kernels: dict) -> set:
    """The kernels ``called``, and those they call: a kernel loaded from the cache brings its callees
    compiled in, and their own dispatchers are never asked."""
    reached, todo = set(), list(called)
    while todo:
        kernel = todo.pop()
        if kernel not in reached:
            reached.add(kernel)
            todo.extend(kernels.get(kernel, ()))
    return reached


def _is_cached_njit(decorator: ast.expr) -> bool:
    call = isinstance(decorator, ast.Call) and ast.unparse(decorator.func) == "numba.njit"
    options = {k.arg: ast.literal_eval(k.value) for k in decorator.keywords} if call else {}
    return call and options.get("cache") is True and options.get("inline") != "always"


@pytest.mark.parametrize("package", ["offboard", "onboard"])
def test_each_compile_command_calls_every_cached_kernel_of_its_side(package):
    kernels = _kernels(package)
    done = subprocess.run([sys.executable, "-c", SCRIPT, package, json.dumps(sorted(kernels))], cwd=ROOT,
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    called = {tuple(k) for k in json.loads(done.stdout.splitlines()[-1])}
    assert set(kernels) - _reached(called, kernels) == set()


def test_the_kernels_found_are_each_sides_own():
    offboard, onboard = set(_kernels("offboard")), set(_kernels("onboard"))
    assert {("offboard.perception.occupancy", "_integrate_frame"), ("offboard.planning.belief", "_scale_seen_mass"),
            ("offboard.search.repeat_codec", "_decode")} <= offboard
    assert ("offboard.perception.occupancy", "_to_cubes") not in offboard  # inlined into its callers
    assert _kernels("offboard")[("offboard.perception.occupancy", "_cast_rays")] == {("offboard.perception.occupancy",
                                                                                        "_cast_one")}
    assert onboard == {("onboard.sim.render", f) for f in ("_projected_bounds", "_bin_boxes", "_cast")}
