"""docs/architecture.md, the map of the code, is true: its module table is the code's, every path
it names exists, and the floors it draws are the imports the packages make."""
from __future__ import annotations

import ast
import importlib.util
import re
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "architecture.md"
README = REPO / "README.md"


def _code_map():
    spec = importlib.util.spec_from_file_location("code_map", REPO / "scripts" / "code_map.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look their module up while the class is made
    spec.loader.exec_module(module)
    return module


code_map = _code_map()

#: A path the map names: a folder or file of the repository, in backticks.
_PATH = re.compile(r"`((?:[\w.-]+/)+[\w.-]*)`")


#: The repository's own folders: a path starting elsewhere is a run folder's or an FMU's.
_TOP = {p.name for p in REPO.iterdir() if p.is_dir() and not p.name.startswith(".")} - {"out", "build"}


def _named_paths(text: str) -> set[str]:
    return {m.group(1) for m in _PATH.finditer(text) if m.group(1).split("/")[0] in _TOP}


def test_the_module_table_is_the_code_s():
    """Every package's modules, no more, no fewer, each with its own docstring's first line."""
    assert code_map.main(["--check"]) == 0, "run python scripts/code_map.py --write"


def test_the_check_sees_a_module_the_table_lacks(tmp_path):
    stale = code_map.replaced(DOC.read_text(encoding="utf-8"), code_map.table().replace(
        "`monitor/cli.py`", "`monitor/gone.py`"))
    doc = tmp_path / "architecture.md"
    doc.write_text(stale, encoding="utf-8")
    assert code_map.main(["--check", "--doc", str(doc)]) == 1


@pytest.mark.parametrize("document", (DOC, README), ids=("architecture", "readme"))
def test_every_path_the_map_names_exists(document):
    text = document.read_text(encoding="utf-8")
    if code_map.BEGIN in text:          # the generated table lists real files; its docstrings may name run-folder paths
        text = text[:text.index(code_map.BEGIN)] + text[text.index(code_map.END):]
    missing = sorted(p for p in _named_paths(text)
                     if not (REPO / p.rstrip("/")).exists())
    assert not missing, f"{document.name} names paths that do not exist: {missing}"


def _readme_architecture() -> str:
    text = README.read_text(encoding="utf-8")
    start = text.index("## Architecture")
    return text[start:text.index("\n## ", start + 1)]


def test_the_readme_points_to_the_map_and_names_only_real_modules():
    section = _readme_architecture()
    assert "docs/architecture.md" in section
    modules = re.findall(r"`(\w+)\.py`", section)
    known = {p.stem for p in REPO.rglob("*.py") if ".venv" not in p.parts}
    assert set(modules) <= known, sorted(set(modules) - known)


def _project_imports(folder: Path, roots: set[str]) -> set[str]:
    found = set()
    for path in folder.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found & roots


def test_each_package_imports_only_lower_floors():
    """The floors the map draws: a package imports fourbar_common and packages on lower floors only."""
    floors = {"fourbar_common": 0, "mechanism_model": 0}
    floors.update({p.folder: p.floor for p in code_map.PACKAGES if "/" not in p.folder})
    upward = {}
    for name, floor in floors.items():
        if name == "mechanism_model":
            continue
        folder = REPO / name
        imports = _project_imports(folder, set(floors)) - {name, "fourbar_common"}
        if name == "fmu_src":
            imports -= {"mechanism_model"}      # the build packages the FMU's run-time
        bad = {other for other in imports if floors[other] >= floor}
        if bad:
            upward[name] = sorted(bad)
    assert not upward, f"imports that are not to a lower floor: {upward}"
