"""``syt-offboard compile`` and ``syt-onboard compile`` (``make`` runs both) fill numba's on-disk cache
with every kernel of their side, so that a later process compiles none of them: each run here is a
fresh process on an empty ``NUMBA_CACHE_DIR``."""

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# compile_kernels() again, in a process that names every compilation numba starts (a cache miss)
SCRIPT = """
import json
from numba.core import event

compiled = []

class Compiled(event.Listener):
    def on_start(self, ev):
        function = ev.data["dispatcher"].py_func
        compiled.append(f"{function.__module__}.{function.__qualname__}")

    def on_end(self, ev):
        pass

event.register("numba:compile", Compiled())
from offboard.kernel_cache import compile_kernels

compile_kernels()
print(json.dumps(compiled))
"""


def _run(cache_dir: Path, *argv: str) -> str:
    done = subprocess.run([sys.executable, *argv], cwd=ROOT, env={**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)},
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr
    return done.stdout


def _kernels(package: str) -> set[str]:
    """``module.function`` of every ``numba.njit`` function of ``package`` that numba caches on its
    own: not those inlined into their callers (``inline="always"``), which are compiled into them."""
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and any(_is_cached_njit(d) for d in node.decorator_list):
                found.add(f"{path.stem}.{node.name}")
    return found


def _indexed(cache_dir: Path) -> set[str]:
    """The kernels numba's cache holds: ``module.function-line.py311.nbi``, one a kernel."""
    return {path.name.split("-")[0] for path in cache_dir.rglob("*.nbi")}


def _is_cached_njit(decorator: ast.expr) -> bool:
    call = isinstance(decorator, ast.Call) and ast.unparse(decorator.func) == "numba.njit"
    options = {k.arg: ast.literal_eval(k.value) for k in decorator.keywords} if call else {}
    return call and options.get("cache") is True and options.get("inline") != "always"


@pytest.mark.long
def test_after_the_offboard_command_a_search_compiles_none_of_its_kernels(tmp_path):
    _run(tmp_path, "-m", "offboard.cli", "compile")
    assert _kernels("offboard") - _indexed(tmp_path) == set()  # each compiled and cached
    again = json.loads(_run(tmp_path, "-c", SCRIPT).splitlines()[-1])
    assert [name for name in again if name.startswith("offboard.")] == []  # the search's calls: all loaded


@pytest.mark.long
def test_the_onboard_command_caches_the_simulators_renderer(tmp_path):
    _run(tmp_path, "-m", "onboard.cli", "compile")
    assert _kernels("onboard") == _indexed(tmp_path) == {"render._projected_bounds", "render._bin_boxes", "render._cast"}


def test_the_kernels_found_are_each_sides_own():
    kernels = _kernels("offboard")
    assert {"occupancy._integrate_frame", "belief._scale_seen_mass", "repeat_codec._decode"} <= kernels
    assert "occupancy._to_cubes" not in kernels  # inlined into its callers
    assert "render._cast" not in kernels and "render._cast" in _kernels("onboard")
