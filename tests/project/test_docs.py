"""The project's documents stay true to the code: every function the equation index names
exists, every relative link resolves, the README keeps its shape, and nothing cites a
document outside the repository."""

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted((ROOT / "docs").glob("*.md"))
PACKAGES = ("program", "physics", "protocol", "firmware_py", "plant_emulator", "hil")
DOTTED = re.compile(r"`((?:" + "|".join(PACKAGES) + r")(?:\.\w+)+)`")


def _resolve(dotted: str):
    """The object a dotted name names: the longest importable module prefix, then attributes."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for name in parts[cut:]:
            obj = getattr(obj, name)
        return obj
    raise ModuleNotFoundError(dotted)


def _names(text: str) -> list[str]:
    return sorted(set(DOTTED.findall(text)))


def test_the_equation_index_names_only_what_exists():
    names = _names((ROOT / "docs" / "EQUATIONS.md").read_text())
    assert len(names) > 60
    missing = []
    for name in names:
        try:
            _resolve(name)
        except (ModuleNotFoundError, AttributeError):
            missing.append(name)
    assert not missing


def test_the_resolver_sees_a_missing_name():
    with pytest.raises(AttributeError):
        _resolve("physics.lugre.no_such_function")


@pytest.mark.parametrize("doc", DOCS + [ROOT / "README.md"], ids=lambda p: p.name)
def test_relative_links_resolve(doc):
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", doc.read_text()):
        assert (doc.parent / target).exists(), f"{doc.name}: {target}"


def test_the_readme_is_a_guide_with_a_two_command_quick_start():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    quick = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    block = quick.split("```sh", 1)[1].split("```", 1)[0]
    commands = [line.split("#")[0].strip() for line in block.splitlines() if line.split("#")[0].strip()]
    assert commands == ["make demo", "make test"]
    assert "in progress" not in text.lower()


def test_nothing_cites_a_document_outside_the_repository():
    """Every project document named in the tree (an upper-case name with .md; lower-case ones
    are the reports the commands write) is one of the repository's own, and no path climbs
    out of it."""
    skip = {".venv", ".git", "hil-out", ".numba-cache"}
    sources = [p for p in ROOT.rglob("*") if p.suffix in (".py", ".toml", ".md", ".dbc")
               and not skip & set(p.relative_to(ROOT).parts)]
    ours = {p.name for p in ROOT.rglob("*.md") if not skip & set(p.relative_to(ROOT).parts)}
    cited = {(str(p.relative_to(ROOT)), name) for p in sources
             for name in re.findall(r"\b[A-Z][A-Z_]*\.md\b", p.read_text(errors="replace"))}
    assert not [c for c in cited if c[1] not in ours]
    climbing = re.compile(r"\.\./(?:\.\./)*[A-Za-z]")
    assert not [str(p.relative_to(ROOT)) for p in sources if p.suffix == ".md" and climbing.search(p.read_text())]
