"""The packages' layering (docs/ARCHITECTURE.md): each imports only those below it, the
plant nothing of the controller, and no two modules import each other."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ALLOWED = {
    "physics": set(),
    "protocol": {"physics"},
    "firmware_py": {"physics", "protocol"},
    "plant_emulator": {"physics", "protocol"},
    "hil": {"physics", "protocol", "firmware_py", "plant_emulator"},
}


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path, root: Path = ROOT) -> set[str]:
    """Absolute names of the project's modules `path` imports (relative imports resolved)."""
    tree = ast.parse(path.read_text(), filename=str(path))
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


def project_modules():
    for package in ALLOWED:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield package, path


@pytest.mark.parametrize("package", list(ALLOWED))
def test_each_package_imports_only_those_below_it(package):
    wrong = [(str(path.relative_to(ROOT)), name) for pkg, path in project_modules() if pkg == package
             for name in sorted(imports_of(path)) if name.split(".")[0] not in ALLOWED[package] | {package}]
    assert not wrong, wrong


def test_no_two_modules_import_each_other():
    modules = {_module_name(path): path for _, path in project_modules()}
    edges = {name: {m for m in imports_of(path) if m in modules and m != name} for name, path in modules.items()}
    cycles = sorted((a, b) for a, targets in edges.items() for b in targets if a in edges.get(b, ()) and a < b)
    assert not cycles, cycles


def test_the_check_sees_an_upward_import(tmp_path):
    """The checker itself: a module of the plant importing the controller is found."""
    bad = tmp_path / "plant_emulator" / "probe.py"
    bad.parent.mkdir()
    bad.write_text("from firmware_py.kinematics import ik_into\nfrom . import hydraulics\n")
    names = imports_of(bad, tmp_path)
    assert "firmware_py.kinematics" in names and "plant_emulator.hydraulics" in names
