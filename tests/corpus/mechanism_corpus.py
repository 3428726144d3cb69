"""The corpus of mechanism expressions (mechanism_expressions.toml) and the files made from it:
one home for tests/test_mechanism_untrusted.py and benchmarks/untrusted_expressions.py."""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CORPUS", "BASE", "FIELDS", "Case", "corpus", "toml_string", "mechanism_file", "shown"]

REPO = Path(__file__).resolve().parents[2]
CORPUS = Path(__file__).resolve().parent / "mechanism_expressions.toml"
#: The mechanism the expressions are put into (its parameters: L1 = 3, L2 = 1, L3 = 4, L4 = 2.5,
#: m2 = m3 = m4 = 1, g = 9.81).
BASE = REPO / "fmu_src" / "mechanisms" / "fourbar.toml"
#: Where an expression goes: field name -> (the field as a message names it, the line of
#: fourbar.toml it replaces (its first occurrence: the crank's length), the replacement).
FIELDS = {
    "length": ("bodies[0] 'crank'.length", 'length = "L2"', "length = {}"),
    "point": ("ground.points.O4[0]", 'O4 = ["L1", 0]', "O4 = [{}, 0]"),
}


@dataclass(frozen=True)
class Case:
    text: str
    expect: str        # "load" or "refuse"
    label: str         # for test ids and tables


def corpus() -> tuple[Case, ...]:
    """The corpus entries, expanded (``repeat``, ``prefix``, ``suffix``: see the file's header)."""
    out = []
    for k, entry in enumerate(tomllib.loads(CORPUS.read_text(encoding="utf-8"))["case"]):
        n = entry.get("repeat", 1)
        if "prefix" in entry or "suffix" in entry:
            text = entry.get("prefix", "") * n + entry["text"] + entry.get("suffix", "") * n
        else:
            text = entry["text"] * n
        head = entry.get("prefix", "") + entry["text"] + entry.get("suffix", "")
        label = repr(head)[:40] + (f" x{n}" if n > 1 else "")
        out.append(Case(text, entry["expect"], f"{k:03d} {label}"))
    return tuple(out)


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string (JSON's escapes are TOML's; DEL must be escaped too)."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def mechanism_file(folder: Path, text: str, field: str = "length") -> Path:
    """fourbar.toml with ``text`` as the crank's length or as the x of ground point O4, written
    to ``folder``/untrusted.toml."""
    _, line, replacement = FIELDS[field]
    path = Path(folder) / "untrusted.toml"
    path.write_text(BASE.read_text(encoding="utf-8").replace(line, replacement.format(toml_string(text)), 1),
                    encoding="utf-8")
    return path


def shown(text: str) -> str:
    """How a refusal quotes the text (docs/mechanisms.md: cut after 80 characters)."""
    return repr(text) if len(text) <= 80 else repr(text[:80])
