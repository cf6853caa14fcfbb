"""The layering (docs/ARCHITECTURE.md): each package imports only those below it, the plant
nothing of the controller; inside firmware_py and hil each part imports only the parts on
the floors below it; and no two modules import each other. Imports inside functions count.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ALLOWED = {
    "program": set(),
    "physics": {"program"},
    "protocol": {"program", "physics"},
    "firmware_py": {"program", "physics", "protocol"},
    "plant_emulator": {"program", "physics", "protocol"},
    "hil": {"program", "physics", "protocol", "firmware_py", "plant_emulator"},
}
# the parts of a package (a subpackage or a module) floor by floor, lowest first: a part
# imports parts of lower floors only (and itself)
FLOORS = {
    "firmware_py": [
        {"config", "checkpoint"},                     # its configuration; a state checkpoint
        {"mechanics"},                                # the mechanism's model
        {"motion_control"},                           # estimation and control
        {"supervision"},                              # faults, limits, waypoints' admission
        {"hostlink", "rig_model", "status"},          # the controller's ports and its rig
        {"controller"},                               # one cycle of the controller
        {"runtime"},                                  # the controller on the bus
        {"__main__"},
    ],
    "hil": [
        {"logdata_canopen"},
        {"logdata", "plotting", "injection", "identification", "experiments", "host", "processes", "in_process"},
        {"fuzz"},
        {"logquery", "metrics", "monitor", "reference_rebuild", "scenario", "estimates"},
        {"design", "report"},
        {"runner", "tools"},
        {"scenarios"},
        {"faults", "campaign"},
        {"cli"},
    ],
}


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path, root: Path = ROOT) -> set[str]:
    """Absolute names of the project's modules `path` imports, at any depth of the file
    (inside functions too; relative imports resolved)."""
    return _imports_of(path, root, path.read_text())


@functools.cache
def _imports_of(path: Path, root: Path, text: str) -> set[str]:
    tree = ast.parse(text, filename=str(path))
    package = _module_name(path, root).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
            out.add(base)
            out |= {f"{base}.{alias.name}" for alias in node.names}
    return {name for name in out if name.split(".")[0] in ALLOWED}


def project_modules(root: Path = ROOT):
    for package in ALLOWED:
        for path in sorted((root / package).rglob("*.py")):
            yield package, path


def wrong_package_imports(root: Path = ROOT) -> list[tuple[str, str]]:
    return [(str(path.relative_to(root)), name) for package, path in project_modules(root)
            for name in sorted(imports_of(path, root)) if name.split(".")[0] not in ALLOWED[package] | {package}]


def floor_of(package: str, part: str) -> int:
    for k, floor in enumerate(FLOORS[package]):
        if part in floor:
            return k
    raise KeyError(f"{package}.{part} is on no floor of tests/project/test_layering.py's FLOORS")


def wrong_floor_imports(root: Path = ROOT) -> list[tuple[str, str]]:
    """(file, imported name) for every import inside firmware_py or hil that does not go down."""
    wrong = []
    for package, path in project_modules(root):
        if package not in FLOORS:
            continue
        parts = _module_name(path, root).split(".")
        if len(parts) < 2:
            continue                                   # the package's __init__
        here = floor_of(package, parts[1])
        for name in sorted(imports_of(path, root)):
            target = name.split(".")
            if target[0] != package or len(target) < 2 or target[1] == parts[1]:
                continue
            if not (root / package / target[1]).is_dir() and not (root / package / f"{target[1]}.py").is_file():
                continue                               # a name imported from the package's __init__
            if floor_of(package, target[1]) >= here:
                wrong.append((str(path.relative_to(root)), name))
    return wrong


@pytest.mark.parametrize("package", list(ALLOWED))
def test_each_package_imports_only_those_below_it(package):
    wrong = [(path, name) for path, name in wrong_package_imports() if path.startswith(package + "/")]
    assert not wrong, wrong


def test_every_part_is_on_a_floor():
    for package in FLOORS:
        for path in sorted((ROOT / package).iterdir()):
            if path.name.startswith(("_", ".")) and path.name != "__main__.py" or path.name in ("data",):
                continue
            if path.is_dir() and not (path / "__init__.py").exists():
                continue
            if path.is_file() and path.suffix != ".py":
                continue
            floor_of(package, path.stem)


def test_inside_firmware_py_and_hil_every_import_goes_down():
    wrong = wrong_floor_imports()
    assert not wrong, wrong


def test_no_two_modules_import_each_other():
    modules = {_module_name(path): path for _, path in project_modules()}
    edges = {name: {m for m in imports_of(path) if m in modules and m != name} for name, path in modules.items()}
    cycles = sorted((a, b) for a, targets in edges.items() for b in targets if a in edges.get(b, ()) and a < b)
    assert not cycles, cycles


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    """A copy of the tree's packages (each planted check adds its file, then takes it out)."""
    root = tmp_path_factory.mktemp("tree")
    for package in ALLOWED:
        for path in (ROOT / package).rglob("*.py"):
            copy = root / path.relative_to(ROOT)
            copy.parent.mkdir(parents=True, exist_ok=True)
            copy.write_text(path.read_text())
    return root


@pytest.fixture
def plant(tree):
    """plant(relative, text): one more file in the copy, for this test only; the copy's root."""
    planted = []

    def put(relative: str, text: str) -> Path:
        path = tree / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        planted.append(path)
        return tree
    yield put
    for path in planted:
        path.unlink()


def test_the_check_sees_an_upward_import(plant):
    """The checker itself: a module of the plant importing the controller is found."""
    root = plant("plant_emulator/probe.py", "from firmware_py.mechanics.kinematics import ik_into\n")
    assert ("plant_emulator/probe.py", "firmware_py.mechanics.kinematics") in wrong_package_imports(root)


def test_the_check_sees_a_back_edge_inside_hil(plant):
    """The design tools importing a scenario (a floor above them) is found."""
    root = plant("hil/design/probe.py", "from hil.scenarios.pm import PmCircle\n")
    assert ("hil/design/probe.py", "hil.scenarios.pm") in wrong_floor_imports(root)


def test_the_check_sees_an_upward_import_inside_a_function(plant):
    """An import hidden in a function body that goes up a floor is found."""
    root = plant("firmware_py/mechanics/probe.py",
                 "def f():\n    from firmware_py.controller import Controller\n    return Controller\n")
    assert ("firmware_py/mechanics/probe.py", "firmware_py.controller") in wrong_floor_imports(root)


def imports_of_test_modules(root: Path = ROOT) -> list[tuple[str, str]]:
    """(test file, name) for each test module importing another one (shared code lives in
    tests/support)."""
    wrong = []
    for path in sorted((root / "tests").rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            wrong += [(str(path.relative_to(root)), n) for n in names if n.split(".")[-1].startswith("test_")
                      or n.split(".")[-1] == "conftest"]
    return wrong


def test_no_test_module_imports_another():
    assert imports_of_test_modules() == []


def test_the_check_sees_a_test_importing_a_test(plant):
    plant("tests/hil/test_a.py", "from tests.protocol.test_bus import GROUP\n")
    root = plant("tests/hil/test_b.py", "from tests.support.buses import GROUP\n")
    assert imports_of_test_modules(root) == [("tests/hil/test_a.py", "tests.protocol.test_bus")]
