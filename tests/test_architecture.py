"""The three parts stay independent: they meet only through FMI and through files.

Static scan of every module's imports (``ast``), so a lazy import inside a function
counts too.  ``sweep`` and ``diagnose`` are the integration packages and may use orchestrator and monitor.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest
from support import REPO

PARTS = ("fmu_src", "orchestrator", "monitor")
# What the FMU's run-time code (shipped in resources/) may import besides the stdlib.
FMU_RUNTIME_ALLOWED = {"numpy", "scipy", "pythonfmu", "mechanism_model"}


def imported_roots(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    roots = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


@pytest.mark.parametrize("part", PARTS)
def test_parts_do_not_import_each_other(part):
    others = (set(PARTS) - {part}) | {"sweep", "diagnose"}
    if part != "fmu_src":
        others.add("mechanism_model")      # the FMU's run-time package, reachable only via FMI
    offenders = {}
    for path in sorted((REPO / part).rglob("*.py")):
        bad = imported_roots(path) & others
        if bad:
            offenders[str(path.relative_to(REPO))] = sorted(bad)
    assert not offenders, f"{part} imports other parts: {offenders}"


def test_the_view_imports_none_of_the_parts():
    """fourbar-view reads a run folder's files only: no part, integration package or FMU code."""
    forbidden = set(PARTS) | {"sweep", "diagnose", "mechanism_model"}
    offenders = {str(p.relative_to(REPO)): sorted(imported_roots(p) & forbidden)
                 for p in sorted((REPO / "view").rglob("*.py")) if imported_roots(p) & forbidden}
    assert not offenders, offenders


def test_the_shared_helpers_need_only_the_standard_library():
    """fourbar_common is imported by every part, so it may import none of them (nor anything else
    but the standard library; its contract modules may use numpy, which every reader of a CSV's
    columns already has)."""
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    for path in sorted((REPO / "fourbar_common").rglob("*.py")):
        allowed = stdlib | ({"numpy", "fourbar_common"} if "contract" in path.parts else set())
        assert imported_roots(path) <= allowed, path


def _relative_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            found.add(node.module.split(".")[0])
    return found


@pytest.mark.parametrize("package", ("monitor", "orchestrator", "sweep", "diagnose", "view"))
def test_modules_import_each_other_without_a_circle(package):
    """Within a package the imports (lazy ones included) form a DAG: each module can be read
    knowing only the ones below it."""
    graph = {p.stem: _relative_imports(p) for p in (REPO / package).glob("*.py") if p.stem != "__init__"}
    done: set[str] = set()

    def visit(name: str, path: tuple[str, ...]) -> None:
        assert name not in path, f"{package}: import circle {' -> '.join(path + (name,))}"
        if name in done:
            return
        for dep in graph.get(name, ()):
            visit(dep, path + (name,))
        done.add(name)

    for name in graph:
        visit(name, ())


def test_one_place_decides_an_alarm():
    """Only monitor.detector (alarm_event, which every detector calls) creates alarm events."""
    makers = []
    for path in sorted((REPO / "monitor").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "Event":
                kinds = [a.value for a in node.args[1:2] if isinstance(a, ast.Constant)]
                if "alarm" in kinds:
                    makers.append(path.name)
    assert makers and set(makers) == {"detector.py"}, makers


def test_case_and_sweep_validators_share_one_toolkit():
    """The checks both file kinds need (tables, numbers, integers, booleans, names, the grid)
    are defined once, in orchestrator/validation.py; the two validators only use them."""
    shared = {"table", "number", "integer", "boolean", "text", "identifier", "whole_steps", "unknown_keys",
              "problem", "missing", "show_value", "kind_of", "is_number", "read_toml", "grid_steps"}
    definitions: dict[str, list[str]] = {}
    for path in (REPO / "orchestrator" / "validation.py", REPO / "orchestrator" / "config.py",
                 REPO / "orchestrator" / "case.py", REPO / "sweep" / "config.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef) and node.name in shared:
                definitions.setdefault(node.name, []).append(path.name)
    assert definitions == {name: ["validation.py"] for name in shared}, definitions


def test_fmu_runtime_needs_only_numpy_and_scipy():
    stdlib = set(sys.stdlib_module_names)
    files = sorted((REPO / "fmu_src" / "mechanism_model").glob("*.py"))
    assert files
    for path in files:
        extra = imported_roots(path) - stdlib - FMU_RUNTIME_ALLOWED
        assert not extra, f"{path.name} imports {sorted(extra)}: the FMU ships only numpy/scipy needs"


# What the native FMU's C may include: the C standard library, the FMI 2.0 headers and its own.
C_STANDARD_HEADERS = {"float.h", "math.h", "stdarg.h", "stddef.h", "stdio.h", "stdlib.h", "string.h"}
FMI_HEADERS = {"fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"}


def test_native_fmu_runtime_is_the_c_standard_library_only(native_fmu):
    import re
    import zipfile

    with zipfile.ZipFile(native_fmu) as z:
        sources = {Path(n).name: z.read(n).decode() for n in z.namelist()
                   if n.startswith("sources/") and n.endswith((".c", ".h"))}
    own = set(sources) - FMI_HEADERS
    allowed = C_STANDARD_HEADERS | FMI_HEADERS | own
    for name in sorted(own):
        included = set(re.findall(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', sources[name], flags=re.M))
        assert included <= allowed, f"{name} includes {sorted(included - allowed)}"
    # The equations are generated, never written by hand: the hand-written C has no copy.
    from fmu_src.native_build import GENERATED, HAND_WRITTEN
    assert set(GENERATED) <= own and not set(GENERATED) & set(HAND_WRITTEN)


def test_generated_code_is_not_committed():
    import subprocess

    from fmu_src.native_build import GENERATED
    tracked = subprocess.run(["git", "ls-files", "fmu_src"], cwd=REPO, capture_output=True, text=True)
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    names = {Path(line).name for line in tracked.stdout.split()}
    assert not names & (set(GENERATED) | {"equations.py"}), "generated files are tracked by git"


#: What told the old single FmuInstance class which FMI flavour it drove (issue 38, item 3).
FLAVOUR_FLAGS = {"fmi3", "model_exchange", "fmiVersion", "fmi_type", "FMI_TYPE", "PREFIX"}


def test_fmi_flavours_are_classes_not_flags():
    """orchestrator's FMU instance is one class per FMI flavour (orchestrator.instance.FLAVOURS),
    chosen once by instance_for: no method of the FMI layer tests the FMI version or interface type."""
    branches = []
    for name in ("fmi_instance.py", "fmi_versions.py", "fmi_interfaces.py", "instance.py"):
        tree = ast.parse((REPO / "orchestrator" / name).read_text())
        for cls in (n for n in tree.body if isinstance(n, ast.ClassDef)):
            for node in ast.walk(cls):
                if isinstance(node, (ast.If, ast.IfExp)):
                    used = {n.id for n in ast.walk(node.test) if isinstance(n, ast.Name)}
                    used |= {n.attr for n in ast.walk(node.test) if isinstance(n, ast.Attribute)}
                    if used & FLAVOUR_FLAGS:
                        branches.append(f"{name}:{node.lineno} ({cls.name})")
    assert not branches, f"flavour branches in the FMI layer: {branches}"


def test_the_package_description_fits_what_it_builds():
    """pyproject's description (issue 38, item 5): any planar mechanism, the four-bar the default;
    FMI 2.0 and 3.0; pythonfmu and native C (it said "Four-bar linkage FMI 2.0 co-simulation")."""
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    text = project["description"]
    for says in ("planar mechanism", "four-bar linkage by default", "FMI 2.0 and 3.0", "pythonfmu", "native C"):
        assert says in text, f"pyproject.toml description does not say {says!r}: {text}"
    first = (REPO / "fmu_src" / "__init__.py").read_text(encoding="utf-8").split("\n\n")[0]
    assert "FMI 2.0 and 3.0" in first and "four-bar by default" in first, first



def _benchmark_modules() -> set[str]:
    return {p.stem for p in (REPO / "benchmarks").glob("*.py")}


def test_no_test_imports_benchmark_code():
    """Tests depend on the package, never on benchmarks/ (issue 38, item 4): what tests and
    benchmarks share (tolerances, flavour tables, host runners, the configuration rules) lives in
    the package, which the benchmarks import.  A test may still run a benchmark as a program."""
    benchmarks = _benchmark_modules()
    assert {"fmi_flavours", "fmi_hosts", "doc_figures"} <= benchmarks      # the scan sees them
    offenders = {}
    for path in sorted((REPO / "tests").rglob("*.py")):
        bad = imported_roots(path) & (benchmarks | {"benchmarks"})
        if bad:
            offenders[str(path.relative_to(REPO))] = sorted(bad)
    assert not offenders, f"tests import benchmark modules: {offenders}"


def test_no_test_puts_benchmarks_on_the_import_path():
    """Neither tests/support.py nor any test adds benchmarks/ to sys.path (they used to, to import it)."""
    offenders = []
    for path in sorted((REPO / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if (isinstance(node, ast.Call) and ast.unparse(node.func) in ("sys.path.insert", "sys.path.append")
                    and "benchmarks" in ast.unparse(node)):
                offenders.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert not offenders, offenders
