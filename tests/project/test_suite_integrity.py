"""Guard against a suite that silently runs less than it has: every `test_*` function in
the files pytest was asked to run must have been collected, and every file under tests/
that defines tests must be named so that pytest collects it."""

import ast
from collections import Counter
from pathlib import Path

import pytest

TESTS_DIR = Path(__file__).resolve().parents[1]


def _test_definitions(path: Path) -> list[str]:
    """Names of test functions as written, duplicates included (Class.method for methods)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test"):
            names.append(node.name)
        elif isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
            names += [f"{node.name}.{f.name}" for f in node.body
                      if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)) and f.name.startswith("test")]
    return names


def _defined_tests(path: Path) -> set[str]:
    return {name.rpartition(".")[2] for name in _test_definitions(path)}


def _redefined(path: Path) -> list[str]:
    return sorted(name for name, n in Counter(_test_definitions(path)).items() if n > 1)


def _requested_files(config) -> list[Path]:
    files = []
    for arg in config.args or [str(TESTS_DIR)]:
        path = Path(config.invocation_params.dir, arg.split("::")[0]).resolve()
        if "::" in arg:
            continue     # a single test node was requested: nothing more to demand
        if path.is_dir():
            files += sorted(path.rglob("test_*.py"))
        elif path.suffix == ".py":
            files.append(path)
    return files


def test_every_defined_test_is_collected(request):
    collected = {(str(Path(p).resolve()), name) for p, name in request.config.hydrapod_collected}
    files = _requested_files(request.config)
    assert files, "no test files found for this invocation"
    missing = [f"{path.relative_to(TESTS_DIR)}::{name}" for path in files
               for name in sorted(_defined_tests(path)) if (str(path), name) not in collected]
    assert not missing, f"defined but not collected (shadowed name, collection error?): {missing}"


def test_no_test_file_escapes_collection():
    stray = [p.name for p in TESTS_DIR.rglob("*.py")
             if not p.name.startswith("test_") and p.name != "conftest.py" and _defined_tests(p)]
    assert not stray, f"files define tests but pytest will not collect them (name them test_*.py): {stray}"


def test_no_test_is_shadowed_by_a_redefinition():
    shadowed = {p.name: _redefined(p) for p in TESTS_DIR.rglob("test_*.py") if _redefined(p)}
    assert not shadowed, f"a later definition hides the earlier test (never runs): {shadowed}"


def test_guard_detects_shadowing_and_stray_files(tmp_path):
    # The guard itself must be able to fail.
    src = tmp_path / "check_x.py"
    src.write_text("def test_a():\n    pass\n\nclass TestK:\n    def test_b(self):\n        pass\n\n"
                   "def test_a():\n    pass\n")
    assert _redefined(src) == ["test_a"]
    assert _defined_tests(src) == {"test_a", "test_b"}


@pytest.mark.xdist_group("integrity-check")
def test_xdist_groups_reach_the_scheduler(request):
    """Tests sharing one module-scoped run (an xdist_group) go to one worker only if xdist
    tags their node ids with the group: a pytest that ignores the tag (9.x with xdist 3.8)
    splits them, and each worker repeats the run."""
    if request.config.getoption("dist", "no") == "loadgroup":
        assert request.node.nodeid.endswith("@integrity-check"), request.node.nodeid
