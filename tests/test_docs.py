"""README.md and docs/ against the code, so the docs cannot drift unnoticed.

- Every command line a doc shows (code blocks and `inline` spans starting with a tool's name)
  names only options the tool's real ``--help`` lists; every synopsis that does not end in
  ``...`` lists all of them; each tool's reference doc has a table of every option.
- Every exit-code list (README, docs/contracts.md, the tools' docs) says what the ``--help``
  epilogs say, and the epilogs name every exit code the code returns.
- Every relative link (and its #anchor) in README.md and docs/*.md exists, and every ``.md``
  file named anywhere in those docs or in the code's comments and docstrings is in the
  repository.
- Every ```python block in README.md and docs/*.md is executed, as written, on a short real
  run (the slow tests below); a new block without a runner fails
  ``test_every_python_example_has_a_runner``.

- The native FMU's speed-up over the pythonfmu FMU is quoted in docs/benchmarks.md only (the
  table ``benchmarks/native_fmu.py`` writes): no other doc, the tutorial or a ``--help`` repeats
  a number for it. README and docs/mechanisms.md name the FMI 3.0 ``<Name>Native3.fmu``;
  ``fourbar-run --help`` names the FMI versions and interfaces the orchestrator accepts.

Figures quoted in the docs are checked by benchmarks/doc_figures.py (tests/test_doc_figures.py).
"""
from __future__ import annotations

import ast
import contextlib
import importlib
import io
import os
import re
import signal
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from support import REPO

BIN = Path(sys.executable).parent
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]

#: tool -> (module with main(argv), the doc whose table lists every option)
TOOLS = {
    "fourbar-run": ("orchestrator.cli", "docs/orchestrator.md"),
    "fourbar-monitor": ("monitor.cli", "docs/monitor.md"),
    "fourbar-sweep": ("sweep.cli", "docs/sweep.md"),
    "fourbar-diagnose": ("diagnose.cli", "docs/diagnose.md"),
    "fourbar-view": ("view.cli", "docs/view.md"),
    "build_fmu.py": ("build_fmu", "README.md"),
}
TOOL_AT_START = re.compile(r"^(?:\.venv/bin/|python3? )?(fourbar-run|fourbar-monitor|fourbar-sweep|fourbar-diagnose|fourbar-view"
                           r"|build_fmu\.py)(?=\s|$)")
FLAG = re.compile(r"(?<![\w-])--[a-z][\w-]*")


def rel(path: Path) -> str:
    return str(path.relative_to(REPO))


# --- the tools' own --help -----------------------------------------------------------------

_HELP: dict[str, str] = {}


def help_text(tool: str) -> str:
    """What ``TOOL --help`` prints (in-process: the same parser the command uses)."""
    if tool not in _HELP:
        if str(REPO) not in sys.path:
            sys.path.insert(0, str(REPO))
        module = importlib.import_module(TOOLS[tool][0])
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            try:
                code = module.main(["--help"])
            except SystemExit as stop:           # argparse's own exit
                code = stop.code
        assert code in (0, None), f"{tool} --help exited {code}"
        _HELP[tool] = out.getvalue()
    return _HELP[tool]


def options(tool: str) -> set[str]:
    """The long options the tool's --help lists (without --help)."""
    found = set()
    for line in help_text(tool).splitlines():
        lead = re.match(r"^  (-{1,2}\w[\w-]*(?: [^,\s]+)?(?:, -{1,2}\w[\w-]*(?: [^,\s]+)?)*)", line)
        if lead:
            found |= set(FLAG.findall(lead.group(1)))
    return found - {"--help"}


def exit_codes_in(text: str) -> set[int]:
    """Codes in an exit-code list: '0 no alarm, 1 alarm, ...' or '**0** no alarm; **1** ...'."""
    bold = {int(c) for c in re.findall(r"\*\*(\d+)\*\*", text)}
    return bold or {int(c) for c in re.findall(r"(?<![\w.=/(-])(\d+)(?: / \d+)? (?=[a-z(])", text)}


def epilog_codes(tool: str) -> set[int]:
    text = help_text(tool)
    return exit_codes_in(text[text.index("exit status:") + len("exit status:"):])


# --- markdown ----------------------------------------------------------------------------

def code_blocks(text: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced block."""
    return re.findall(r"(?ms)^ *```(\w*)\n(.*?)^ *```", text)


def command_lines(path: Path) -> list[tuple[str, str, int]]:
    """(tool, text, line number) of every command a doc shows: code-block lines (with their
    indented continuation lines) and `inline` spans starting with a tool's name."""
    text = path.read_text(encoding="utf-8")
    found = []
    for _lang, body in code_blocks(text):
        tool = None
        for line in body.splitlines():
            line = re.sub(r"\s#\s.*$", "", line).rstrip()
            start = TOOL_AT_START.match(line)
            if start:
                tool = start.group(1)
                found.append([tool, line, text.count("\n", 0, text.index(body)) + 1])
            elif tool and line.startswith(" ") and line.strip():
                found[-1][1] += " " + line.strip()
            else:
                tool = None
    for span in re.finditer(r"`([^`\n]+)`", text):
        start = TOOL_AT_START.match(span.group(1))
        if start:
            found.append([start.group(1), span.group(1), text.count("\n", 0, span.start()) + 1])
    return [tuple(f) for f in found]


def test_help_parsing_finds_the_options():
    # the parser of --help texts must see flags that are certainly there, or every check below is void
    assert {"--follow", "--detector", "--false-alarm-rate", "--quiet", "--verbose", "--version"} <= options("fourbar-monitor")
    assert {"--fmu", "--set", "--stop", "--quiet"} <= options("fourbar-run")
    assert {"--only", "--out", "--native-out", "--no-validate"} <= options("build_fmu.py")
    assert {0, 1, 2, 3, 130} <= epilog_codes("fourbar-monitor")
    assert exit_codes_in("Exit status: **0** no alarm; **1** alarm; **130** interrupted") == {0, 1, 130}


@pytest.mark.parametrize("tool", sorted(TOOLS))
def test_commands_in_the_docs_use_only_real_options(tool):
    known = options(tool)
    wrong = [f"{rel(doc)}:{line}: {flag} in `{cmd}`"
             for doc in DOCS for t, cmd, line in command_lines(doc) if t == tool
             for flag in FLAG.findall(cmd) if flag not in known]
    assert not wrong, f"options {tool} --help does not list:\n" + "\n".join(wrong)


@pytest.mark.parametrize("tool", sorted(TOOLS))
def test_synopses_are_complete_unless_abridged(tool):
    known = options(tool)
    synopses = [(doc, cmd, line) for doc in DOCS for t, cmd, line in command_lines(doc)
                if t == tool and "[--" in cmd and not cmd.rstrip().endswith("...")]
    problems = [f"{rel(doc)}:{line}: lacks {', '.join(sorted(known - set(FLAG.findall(cmd))))}"
                for doc, cmd, line in synopses if known - set(FLAG.findall(cmd))]
    assert synopses, f"no complete synopsis of {tool} in README.md or docs/"
    assert not problems, f"synopses of {tool} that do not list every option (end one with '...' if abridged):\n" \
                         + "\n".join(problems)


@pytest.mark.parametrize("tool", sorted(t for t, (_m, doc) in TOOLS.items() if doc != "README.md"))
def test_each_tool_has_a_table_of_every_option(tool):
    doc = TOOLS[tool][1]
    rows = re.findall(r"(?m)^\| (`--[^|]*)\|", (REPO / doc).read_text(encoding="utf-8"))
    documented = {flag for cell in rows for flag in FLAG.findall(cell)}
    assert documented == options(tool), (f"{doc}'s option table against {tool} --help: missing "
                                         f"{sorted(options(tool) - documented)}, not an option {sorted(documented - options(tool))}")


def test_every_monitor_option_field_is_documented():
    from dataclasses import fields

    from monitor import MonitorOptions
    from monitor.detectors import detector_class, detector_names
    text = (REPO / "docs" / "monitor.md").read_text(encoding="utf-8")
    every = list(fields(MonitorOptions)) + [f for n in detector_names() for f in fields(detector_class(n).Settings)]
    missing = [f.name for f in every
               if not (f.metadata.get("flag") and f.metadata["flag"] in text) and f"`{f.name}`" not in text]
    assert not missing, f"MonitorOptions fields docs/monitor.md does not name (as a flag or `field`): {missing}"


# --- exit codes --------------------------------------------------------------------------

SIGNAL_CODES = {128 + signal.SIGINT, 128 + signal.SIGTERM}


def codes_of(expr: ast.expr | None, constants: dict[str, int]) -> set[int]:
    """The exit codes an expression of a ``return`` can give: ``2``, ``0 if ok else 1``,
    a module constant, ``128 + signum`` and ``exit_code(signum)`` (the signal statuses)."""
    if isinstance(expr, ast.Constant) and isinstance(expr.value, int) and not isinstance(expr.value, bool):
        return {expr.value}
    if isinstance(expr, ast.IfExp):
        return codes_of(expr.body, constants) | codes_of(expr.orelse, constants)
    if isinstance(expr, ast.Name) and expr.id in constants:
        return {constants[expr.id]}
    if isinstance(expr, ast.BinOp) and isinstance(expr.left, ast.Constant) and expr.left.value == 128:
        return SIGNAL_CODES
    if isinstance(expr, ast.Call) and ast.unparse(expr.func).split(".")[-1] == "exit_code":
        return SIGNAL_CODES
    return set()


def returned_codes(module_name: str) -> set[int]:
    """Exit codes a command's code can return: what its module's ``return`` statements and
    ``sys.exit``/``SystemExit`` calls give (see :func:`codes_of`), and for the monitor
    ``MonitorResult.exit_code``."""
    spec = importlib.util.find_spec(module_name)
    sources = [Path(spec.origin)]
    if module_name == "monitor.cli":
        sources.append(REPO / "monitor" / "summary.py")
    codes: set[int] = set()
    for source in sources:
        tree = ast.parse(source.read_text(encoding="utf-8"))
        constants = {t.id: n.value.value for n in tree.body if isinstance(n, ast.Assign)
                     and isinstance(n.value, ast.Constant) and type(n.value.value) is int
                     for t in n.targets if isinstance(t, ast.Name) and t.id.isupper()}
        if source.name == "summary.py":
            tree = next(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name == "exit_code")
        for node in ast.walk(tree):
            if isinstance(node, ast.Return):
                codes |= codes_of(node.value, constants)
            elif (isinstance(node, ast.Call) and node.args
                  and ast.unparse(node.func) in ("sys.exit", "SystemExit", "exit")):
                codes |= codes_of(node.args[0], constants)
    return codes


@pytest.mark.parametrize("tool", sorted(TOOLS))
def test_help_lists_every_exit_code_the_code_returns(tool):
    documented, returned = epilog_codes(tool), returned_codes(TOOLS[tool][0])
    # helpers in a CLI module may return 0/1 for other reasons; every code must still be documented
    assert returned <= documented, f"{tool}: returns {sorted(returned - documented)} that --help does not list"
    assert documented <= returned | {2}, f"{tool}: --help lists {sorted(documented - returned - {2})} the code never returns"


def doc_exit_list(file: str, marker: str) -> set[int]:
    text = (REPO / file).read_text(encoding="utf-8")
    start = text.index(marker) + len(marker)
    end = text.find("\n\n", start)
    return exit_codes_in(text[start:end if end >= 0 else len(text)])


def test_exit_code_lists_agree_with_the_tools():
    union = set().union(*(epilog_codes(t) for t in TOOLS))
    assert doc_exit_list("README.md", "Every command has `--help`. Exit codes:") == union
    assert doc_exit_list("docs/contracts.md", "## Exit codes (all CLIs)\n") == union
    assert doc_exit_list("docs/monitor.md", "Exit status:") == epilog_codes("fourbar-monitor")
    assert doc_exit_list("docs/sweep.md", "Exit status:") == epilog_codes("fourbar-sweep")
    assert doc_exit_list("docs/diagnose.md", "Exit status:") == epilog_codes("fourbar-diagnose")
    assert doc_exit_list("docs/view.md", "Exit status:") == epilog_codes("fourbar-view")


# --- links and cited documents ----------------------------------------------------------------

def slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"(?ms)^ *```.*?^ *```", "", path.read_text(encoding="utf-8"))
    return {slug(h) for h in re.findall(r"(?m)^#+ (.*)$", text)}


def test_relative_links_and_anchors_exist():
    broken = []
    for doc in DOCS:
        text = re.sub(r"(?ms)^ *```.*?^ *```", "", doc.read_text(encoding="utf-8"))
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            file = (doc.parent / path).resolve() if path else doc
            if not file.exists():
                broken.append(f"{rel(doc)}: ({target}): no such file")
            elif anchor and file.suffix == ".md" and anchor not in anchors(file):
                broken.append(f"{rel(doc)}: ({target}): no heading #{anchor} in {rel(file)}")
    assert not broken, "\n".join(broken)


def cited_md(text: str) -> set[str]:
    return set(re.findall(r"(?<![\w/.-])((?:[\w.-]+/)*[\w-]+\.md)\b", text))


def test_every_cited_md_file_exists():
    sources = DOCS + [p for p in REPO.rglob("*.py") if not ({".venv", "out", "build", ".git"} & set(p.relative_to(REPO).parts))]
    sources += [REPO / "Makefile", REPO / "pyproject.toml"]
    missing = []
    for source in sources:
        text = source.read_text(encoding="utf-8", errors="replace")
        if source.suffix == ".py":       # comments and docstrings, not string data of tests
            tree_text = [line for line in text.splitlines() if "#" in line]
            try:
                tree = ast.parse(text)
                tree_text += [ast.get_docstring(n) or "" for n in ast.walk(tree)
                              if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef))]
            except SyntaxError:
                tree_text = [text]
            text = "\n".join(tree_text)
        for name in cited_md(text):
            if not any((base / name).exists() for base in (REPO, source.parent, REPO / "docs")):
                missing.append(f"{rel(source)}: {name}")
    assert not missing, "documents cited but not in the repository:\n" + "\n".join(sorted(missing))


def test_the_citation_check_sees_a_missing_document():
    assert cited_md("see NO_SUCH_GUIDE.md §1 and docs/contracts.md") == {"NO_SUCH_GUIDE.md", "docs/contracts.md"}
    assert not (REPO / "NO_SUCH_GUIDE.md").exists()


# --- sweep files shown in docs/sweep.md ------------------------------------------------------

def test_the_l2_step_example_is_the_shipped_file():
    text = (REPO / "docs" / "sweep.md").read_text(encoding="utf-8")
    shown = text[text.index("A complete example, `sweeps/l2_step.toml`"):]
    block = next(body for lang, body in code_blocks(shown) if lang == "toml")
    assert tomllib.loads(block) == tomllib.loads((REPO / "sweeps" / "l2_step.toml").read_text(encoding="utf-8"))


def test_the_random_sample_example_loads(tmp_path):
    from sweep import load_sweep, plan_scenarios
    text = (REPO / "docs" / "sweep.md").read_text(encoding="utf-8")
    shown = text[text.index("A random sample instead of a grid"):]
    block = next(body for lang, body in code_blocks(shown) if lang == "toml")
    sweep_file = tmp_path / "sample.toml"
    sweep_file.write_text(f'case = "{(REPO / "cases" / "case1_normal.toml").as_posix()}"\nstop = 30.0\n'
                          '[monitor]\nmodel = "harmonic"\n' + block)
    plan = plan_scenarios(load_sweep(sweep_file))
    faults = [s for s in plan if s.kind != "none"]
    assert len(faults) == 5 * 2 * 2          # 5 draws x 2 kinds x 2 noise levels, as the text says
    assert len(plan) > len(faults)           # + fault-free runs


# --- Python examples ---------------------------------------------------------------------------

def python_blocks(text: str) -> list[str]:
    """The ```python blocks of a markdown text, in order."""
    return [body for lang, body in code_blocks(text) if lang == "python"]


def python_examples() -> list[tuple[str, str]]:
    return [(rel(doc), block) for doc in DOCS for block in python_blocks(doc.read_text(encoding="utf-8"))]


def first_line(block: str) -> str:
    return next(line for line in block.splitlines() if line.strip())


#: (file, first line of the block) -> the test that runs it
RUNNERS = {
    ("docs/monitor.md", "from monitor import replay, read_exchange, dominant_period, fit_forecaster"):
        "test_monitor_and_diagnose_examples",
    ("docs/diagnose.md", "from diagnose import diagnose"): "test_monitor_and_diagnose_examples",
    ("docs/orchestrator.md", "from orchestrator import load_case, run_case, ConfigError"): "test_orchestrator_example",
    ("docs/sweep.md", "from sweep import load_sweep, plan_scenarios, run_sweep, RUNTIME_COLUMNS"): "test_sweep_example",
    ("docs/fmi_hosts.md", "import numpy as np"): "benchmarks/doc_figures.py (tests/test_doc_figures.py)",
    ("docs/fmi_hosts.md", "from pathlib import Path"): "test_fmi_hosts_examples",
    ("docs/fmi_hosts.md", "from orchestrator import install_pythonfmu_exit_guard"): "test_fmi_hosts_examples",
}


def test_every_python_example_has_a_runner():
    found = {(file, first_line(block)) for file, block in python_examples()}
    assert found, "no ```python block found: the extraction is broken"
    assert not found - set(RUNNERS), f"python examples no test runs: {sorted(found - set(RUNNERS))}"
    assert not set(RUNNERS) - found, f"runners for examples that are gone: {sorted(set(RUNNERS) - found)}"
    # the FMPy block is the one doc_figures executes
    text = (REPO / "docs" / "fmi_hosts.md").read_text(encoding="utf-8")
    assert first_line(python_blocks(text[text.index("### Python API"):])[0]) == "import numpy as np"


def example(file: str, first: str) -> str:
    return next(block for f, block in python_examples() if f == file and first_line(block) == first)


def workspace(tmp_path: Path) -> Path:
    """A folder that looks like the repository to an example (cases/, sweeps/, build/), so it
    writes its out/ there and not into the repository."""
    for name in ("cases", "sweeps", "build"):
        (tmp_path / name).symlink_to(REPO / name, target_is_directory=True)
    return tmp_path


def run_example(where: Path, name: str, code: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``code`` as a script ``name`` in ``where`` with this interpreter, as a user would."""
    script = where / name
    script.write_text(code)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, str(script)], cwd=where, capture_output=True, text=True,
                          timeout=timeout, env=env)
    assert proc.returncode == 0, f"{name} exited {proc.returncode}:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
    return proc


@pytest.mark.slow
def test_monitor_and_diagnose_examples(tmp_path):
    where = workspace(tmp_path)
    # a short Case 2 on the native FMU: the fault at 10 s, 20 s of data
    run = subprocess.run([str(BIN / "fourbar-run"), "cases/case2_fault_L2.toml", "--fmu", "build/FourBarNative.fmu",
                          "--stop", "20", "--out", "out/case2_fault_L2", "--quiet"], cwd=where, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    # each example as written, then a check of what it computed
    run_example(where, "monitor_example.py",
                example("docs/monitor.md", "from monitor import replay, read_exchange, dominant_period, fit_forecaster")
                + "\nassert 10 < r.first_alarm_time < 11, r.first_alarm_time      # the MAE rule sees the L2 step\n")
    assert (where / "out" / "case2_fault_L2" / "monitor" / "summary.json").exists()   # the example's out_dir
    run_example(where, "diagnose_example.py", example("docs/diagnose.md", "from diagnose import diagnose")
                + "\nassert d.verdict == 'explained' and d.best.parameter == 'L2', d.message\n")


@pytest.mark.slow
def test_orchestrator_example(tmp_path):
    where = workspace(tmp_path)
    run_example(where, "orchestrator_example.py",
                example("docs/orchestrator.md", "from orchestrator import load_case, run_case, ConfigError")
                + "\nassert result.ok and result.rows_written == 2001, (result.status, result.rows_written)\n")
    assert (where / "out" / "try" / "exchange.csv").exists()


@pytest.mark.slow
def test_fmi_hosts_examples(tmp_path):
    where = workspace(tmp_path)
    run_example(where, "libcosim_example.py", example("docs/fmi_hosts.md", "from pathlib import Path"))
    run_example(where, "guard_example.py", example("docs/fmi_hosts.md", "from orchestrator import install_pythonfmu_exit_guard"))


@pytest.mark.slow
def test_sweep_example(tmp_path):
    """The smoke sweep from the command line prints what docs/sweep.md shows (its wall time
    aside), then the Python API example runs on the same folder, as a script (Dask's local
    cluster starts worker processes, hence the example's ``__main__`` guard)."""
    where = workspace(tmp_path)
    proc = subprocess.run([str(BIN / "fourbar-sweep"), "sweeps/smoke.toml", "--workers", "2"], cwd=where,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    # a terminal shows the start line (stderr) and then the report (stdout)
    started = [line for line in proc.stderr.splitlines() if line.startswith("fourbar-sweep: smoke:")]
    printed = "\n".join(started + proc.stdout.splitlines())
    printed = printed.replace(str(where.resolve()) + "/", "").replace(str(where) + "/", "")
    text = (REPO / "docs" / "sweep.md").read_text(encoding="utf-8")
    shown = next(body for _lang, body in code_blocks(text) if body.startswith("fourbar-sweep: smoke:"))
    shown_lines = [line for line in shown.splitlines() if line.strip() != "..."]
    wall = re.compile(r"\d+\.\d s$")        # the sweep's wall time varies with load
    assert [wall.sub("…", line) for line in shown_lines] == \
           [wall.sub("…", line) for line in printed.splitlines()[:len(shown_lines)]]
    run_example(where, "sweep_example.py",
                example("docs/sweep.md", "from sweep import load_sweep, plan_scenarios, run_sweep, RUNTIME_COLUMNS"))
    assert (where / "out" / "sweeps" / "smoke" / "plots" / "roc.png").exists()


# --- timings and counts copied from generated files (benchmarks/doc_figures.py, no runs) ------

def copied_check(*args) -> tuple[subprocess.CompletedProcess, set[str]]:
    """``benchmarks/doc_figures.py --copied *args`` run as a program (tests do not import benchmark
    code), and the keys of the lines it marks STALE (``STALE file key quoted ...``)."""
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "doc_figures.py"), "--copied", *map(str, args)],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    return proc, {line.split()[2] for line in proc.stdout.splitlines() if line.startswith("STALE")}


def test_copied_timings_and_counts_match_their_sources():
    proc, stale = copied_check("--check")
    counted = re.search(r"^\d+ of (\d+) quoted figures current", proc.stdout, flags=re.M)
    assert counted and int(counted.group(1)) > 50, ("the copied-figure quotes were not found: check "
                                                    "benchmarks/doc_figures.py\n" + proc.stdout + proc.stderr)
    assert proc.returncode == 0 and not stale, (
        "figures copied by hand differ from the file they come from; update them with "
        "`python benchmarks/doc_figures.py --write --copied`:\n"
        + "\n".join(line for line in proc.stdout.splitlines() if line.startswith("STALE")) + proc.stderr[-2000:])


def test_a_regenerated_benchmark_makes_its_copies_stale(tmp_path):
    for doc in [REPO / "README.md", *(REPO / "docs").glob("*.md")]:   # every quote and every copied source
        (tmp_path / doc.relative_to(REPO)).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / doc.relative_to(REPO)).write_text(doc.read_text(encoding="utf-8"), encoding="utf-8")
    for name in ("sweeps", "cases", "build"):
        (tmp_path / name).symlink_to(REPO / name, target_is_directory=True)
    bench = tmp_path / "docs" / "benchmarks.md"
    text = bench.read_text(encoding="utf-8")
    row = re.search(r"\| pythonfmu \| (\d+) \| (\d+) \|", text)
    bench.write_text(text.replace(row.group(0), f"| pythonfmu | {row.group(1)} | {int(row.group(2)) + 3} |"),
                     encoding="utf-8")
    proc, stale = copied_check("--check", "--root", tmp_path)
    assert proc.returncode == 1 and stale == {"sweep_pythonfmu_s"}, proc.stdout + proc.stderr
    proc, _ = copied_check("--write", "--root", tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    proc, stale = copied_check("--check", "--root", tmp_path)
    assert proc.returncode == 0 and not stale, proc.stdout + proc.stderr


# --- the native FMU's speed-up: one place, docs/benchmarks.md ----------------------------------

#: Where the native FMU's speed-up over the pythonfmu FMU is quoted: the "pythonfmu / native"
#: column of the table benchmarks/native_fmu.py writes (``make benchmarks``).
SPEED_UP_HOME = "docs/benchmarks.md"
_NUM = r"\d+(?:\.\d+)?"
_TIMES = rf"(?:~\s*|about\s+|up\s+to\s+)?{_NUM}(?:\s*[–-]\s*{_NUM})?\s*(?:×|x(?!\w))\**"
#: "19–30× faster", "about 10x faster", "~10x faster", "a speed-up of 7–10×"; not "694× faster
#: than 38 s" (another comparison, with its own reference).
SPEED_UP = re.compile(rf"{_TIMES}\s*(?:faster(?!\s+than)|speed-?up)|(?:speed-?up|faster)\s+(?:of\s+|by\s+)?{_TIMES}",
                      re.IGNORECASE)


def passages(text: str) -> list[str]:
    """Paragraphs, each table row and each option of a --help on its own."""
    return [p for p in re.split(r"\n\s*\n|\n(?=\s*\|)|\n(?=  -)", text) if p.strip()]


def native_speed_up_quotes(text: str) -> list[str]:
    """The speed-up figures in the passages of ``text`` that speak of the native FMU."""
    return [m.group(0) for p in passages(text) if re.search(r"native", p, re.IGNORECASE)
            for m in SPEED_UP.finditer(p)]


def _notebook_text(path: Path) -> str:
    import json

    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    return "\n\n".join("".join(c["source"]) for c in cells)


def test_the_speed_up_check_sees_each_way_it_was_quoted():
    for quoted in ("`build/FourBarNative.fmu`: no\n  Python inside, the same variables, 19–30× faster through FMPy",
                   "The native FMU for other FMI tools, for speed (about 10x faster through",
                   "this notebook uses the native one\n(sympy's C printer, no Python inside; 7–10× faster)",
                   "(the native FMU: no Python in the FMU, ~10x faster)",
                   "| pythonfmu 1.58 s / 1.76 s: native **29.6× / 18.6× faster** (target ≥ 10×: met |",
                   "the native FMU gives a speed-up of 20x"):
        assert native_speed_up_quotes(quoted), quoted
    for other in ("| native 0.055 s (rtol = atol = 2e-9; **694×** faster than 38 s) |",
                  "the native FMU\n\n20 = 20x faster",
                  "  --fmu FMU  e.g. build/FourBarNative.fmu\n  --realtime FACTOR  1 = real time, 20 = 20x faster"):
        assert not native_speed_up_quotes(other), other


def test_the_native_speed_up_is_quoted_only_in_benchmarks_md():
    texts = {rel(path): path.read_text(encoding="utf-8") for path in DOCS if rel(path) != SPEED_UP_HOME}
    texts["examples/tutorial.ipynb"] = _notebook_text(REPO / "examples" / "tutorial.ipynb")
    texts.update({f"{tool} --help": help_text(tool) for tool in TOOLS})
    found = {where: quotes for where, text in texts.items() if (quotes := native_speed_up_quotes(text))}
    assert not found, (f"the native FMU's speed-up is measured and quoted in {SPEED_UP_HOME} only; "
                       f"refer to it there without the number: {found}")
    home = (REPO / SPEED_UP_HOME).read_text(encoding="utf-8")
    assert re.search(r"\| native s \| pythonfmu s \| floor s \| native / floor \| pythonfmu / native \|\n"
                     r"\|[-|]+\|\n\| Case 1 \|(?: [\d.]+x? \|){5}", home), \
        f"{SPEED_UP_HOME} lost the table benchmarks/native_fmu.py writes (pythonfmu / native)"


def test_readme_and_mechanisms_doc_name_the_fmi3_native_fmu():
    assert "<Name>Native3.fmu" in help_text("build_fmu.py")      # what build_fmu.py builds, by its own --help
    for doc in ("README.md", "docs/mechanisms.md"):
        text = (REPO / doc).read_text(encoding="utf-8")
        # every passage that says what build_fmu.py builds lists the FMI 3.0 native FMU too
        lists = [p for p in passages(text) if "build_fmu.py" in p and "Native.fmu" in p]
        assert lists, f"{doc} no longer says what build_fmu.py builds"
        missing = [p for p in lists if "Native3.fmu" not in p]
        assert not missing, f"{doc}: names the FMI 2.0 native FMU but not *Native3.fmu in: {missing}"


def test_fourbar_run_help_names_what_the_orchestrator_accepts():
    from orchestrator.config import FMI_TYPES

    text = " ".join(help_text("fourbar-run").split())
    assert "FMI 2.0 co-simulation FMU" not in text
    assert "FMI 2.0 or 3.0" in text
    assert set(FMI_TYPES) == {"CoSimulation", "ModelExchange"}    # the two interfaces a case may choose
    assert "co-simulation" in text and "model exchange" in text


def test_readme_commands_write_into_out_not_the_repository():
    """A command copied from the README must leave the clone clean: what it writes goes under out/
    (git-ignored), never into the repository's root."""
    text = (REPO / "README.md").read_text(encoding="utf-8")
    written = re.findall(r"--(?:animate|out)\s+(\S+?)`?(?=\s|$)", text)
    assert written, "README.md shows no command that writes a file"
    outside = [path for path in written if not path.startswith(("out/", "DIR", "PATH", "FILE", "FMU", "<"))]
    assert not outside, f"README.md's commands write outside out/: {outside}"


# --- run.json: docs/orchestrator.md's table and docs/contracts.md's block against RunRecord ------

def _record_keys() -> tuple[set[str], dict[str, set[str]]]:
    """run.json's top-level keys and the keys of its nested objects, from fourbar_common/contract/run_record.py."""
    import dataclasses

    from fourbar_common.contract import run_record as rr

    top = {f.name for f in dataclasses.fields(rr.RunRecord)}
    nested = {name: {f.name for f in dataclasses.fields(kind)}
              for name, kind in (("fmu", rr.RecordedFmu), ("experiment", rr.RecordedExperiment),
                                 ("noise", rr.RecordedNoise), ("exchange", rr.RecordedExchange),
                                 ("writer", rr.RecordedWriter))}
    record = rr.RunRecord(status="running", run_id="0" * 32, case="c", fmu=None, experiment=None)
    assert set(record.to_json()) == top      # the dataclass's fields are what to_json writes
    return top, nested


def test_orchestrator_doc_lists_every_run_json_field():
    from fourbar_common.contract.run_record import SCHEMA_VERSION

    text = (REPO / "docs" / "orchestrator.md").read_text(encoding="utf-8")
    start = text.index("| field | meaning |", text.index("`DIR/run.json`"))
    rows = re.findall(r"(?m)^\| ([^|]+) \| ([^\n]+) \|$", text[start:text.index("\n\n", start)])
    documented = {key: meaning for keys, meaning in rows[1:] for key in re.findall(r"`(\w+)`", keys)}
    top, nested = _record_keys()
    assert set(documented) == top, f"docs/orchestrator.md's run.json table: missing {top - set(documented)}, " \
                                   f"not written {set(documented) - top}"
    assert documented["schema"].startswith(f"`{SCHEMA_VERSION}`")
    for name, keys in nested.items():
        shown = re.search(r"`\{([^}]*)\}`", documented[name])
        assert shown and set(re.split(r",\s*", shown.group(1))) == keys, (name, documented[name], keys)


def test_contracts_block_lists_every_run_json_field():
    from fourbar_common.contract.run_record import SCHEMA_VERSION

    text = (REPO / "docs" / "contracts.md").read_text(encoding="utf-8")
    block = re.search(r'(?s)```\n\s*(\{"schema": (\d+), "status".*?)\n\s*```', text)
    assert block and int(block.group(2)) == SCHEMA_VERSION
    top, nested = _record_keys()
    shown = set(re.findall(r'"(\w+)":', block.group(1)))
    assert top <= shown, f"docs/contracts.md's run.json block lacks {top - shown}"
    for name, keys in nested.items():
        inner = re.search(rf'"{name}": \{{([^}}]*)\}}', block.group(1))
        assert inner and keys == set(re.findall(r'(?<!: )(?<!\| )"(\w+)"', inner.group(1)))  # keys, not values, (name, inner and inner.group(1), keys)
