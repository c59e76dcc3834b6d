"""The folder layout is the architecture: onboard and offboard meet only in shared, and inside
offboard each subpackage imports only the ones below it (see each package's ``__init__``)."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FORBIDDEN = {"onboard": {"offboard"}, "offboard": {"onboard"}, "shared": {"onboard", "offboard"}}

# offboard subpackage -> the offboard subpackages it may import (besides itself and shared)
OFFBOARD_LAYERS = {
    "robot": set(),
    "perception": {"robot"},
    "planning": {"perception"},
    "navigation": {"robot", "perception"},
    "search": {"robot", "perception", "planning", "navigation"},
    "experiments": {"robot", "perception", "planning", "navigation", "search"},
    "bench": {"robot", "perception", "planning", "navigation", "search", "experiments"},
    "fuzz": {"robot", "perception", "planning", "navigation", "search", "experiments"},
}
PURE = {"planning": {"zenoh", "rerun"}}  # the planner does no I/O: no transport, no recording
# onboard backend -> the onboard modules it must not import: a robot runs its drivers without the
# simulator, and the simulator runs without the drivers (both share onboard.devices and onboard.config)
ONBOARD_BACKENDS = {"sim": ("onboard.hardware", "onboard.emulators"), "hardware": ("onboard.sim", "onboard.emulators")}


def _imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
    return names


def _imported_packages(path: Path) -> set[str]:
    return {name.split(".")[0] for name in _imported_modules(path)}


def _offboard_subpackages(path: Path) -> set[str]:
    return {name.split(".")[1] for name in _imported_modules(path)
            if name.startswith("offboard.") and name.split(".")[1] in OFFBOARD_LAYERS}


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_packages_import_only_what_the_architecture_allows(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files, f"no sources found under {package}/"
    offenders = {str(f.relative_to(ROOT)): sorted(_imported_packages(f) & FORBIDDEN[package]) for f in files}
    assert {f: bad for f, bad in offenders.items() if bad} == {}


def test_imports_are_absolute_so_the_checks_above_see_them():
    relative = [f"{path.relative_to(ROOT)}:{node.lineno}" for package in FORBIDDEN
                for path in sorted((ROOT / package).rglob("*.py"))
                for node in ast.walk(ast.parse(path.read_text(), filename=str(path)))
                if isinstance(node, ast.ImportFrom) and node.level > 0]
    assert relative == []


@pytest.mark.parametrize("layer", sorted(OFFBOARD_LAYERS))
def test_offboard_layers_import_only_those_below(layer):
    files = sorted((ROOT / "offboard" / layer).rglob("*.py"))
    assert files, f"no sources found under offboard/{layer}/"
    allowed = OFFBOARD_LAYERS[layer] | {layer}
    offenders = {str(f.relative_to(ROOT)): sorted(_offboard_subpackages(f) - allowed) for f in files}
    assert {f: bad for f, bad in offenders.items() if bad} == {}


@pytest.mark.parametrize("layer", sorted(PURE))
def test_pure_layers_do_no_io(layer):
    files = sorted((ROOT / "offboard" / layer).rglob("*.py"))
    assert files, f"no sources found under offboard/{layer}/"
    offenders = {str(f.relative_to(ROOT)): sorted(_imported_packages(f) & PURE[layer]) for f in files}
    assert {f: bad for f, bad in offenders.items() if bad} == {}


@pytest.mark.parametrize("backend", sorted(ONBOARD_BACKENDS))
def test_an_onboard_backend_does_not_import_the_other(backend):
    files = sorted((ROOT / "onboard" / backend).rglob("*.py"))
    assert files, f"no sources found under onboard/{backend}/"
    offenders = {str(f.relative_to(ROOT)): sorted(name for name in _imported_modules(f)
                                                  if name.startswith(ONBOARD_BACKENDS[backend]))
                 for f in files}
    assert {f: bad for f, bad in offenders.items() if bad} == {}


def test_every_offboard_subpackage_has_a_place_in_the_layers():
    packages = {p.parent.name for p in (ROOT / "offboard").glob("*/__init__.py")}
    assert packages <= set(OFFBOARD_LAYERS), sorted(packages - set(OFFBOARD_LAYERS))


def test_offboard_top_level_holds_at_most_three_modules():
    modules = sorted(p.name for p in (ROOT / "offboard").glob("*.py"))
    assert len(modules) <= 3, modules


def test_the_checker_sees_forbidden_imports(tmp_path):
    bad = tmp_path / "x.py"
    bad.write_text("from offboard.robot.robot_client import RobotClient\nimport onboard.agent\n"
                   "from offboard.search import loop\n")
    assert _imported_packages(bad) == {"offboard", "onboard"}
    assert _offboard_subpackages(bad) == {"robot", "search"}
