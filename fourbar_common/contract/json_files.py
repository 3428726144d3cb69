"""Reading and writing the JSON files of a run folder: the one place they are parsed and dumped.

Every contract module of a JSON file (:mod:`.run_record`, :mod:`.summary`, :mod:`.diagnosis`,
:mod:`.sweep_results`) reads its file with :func:`read_json_file` (a regular file only, at most
:data:`MAX_JSON_BYTES`, UTF-8, JSON nested no deeper than Python's parser follows: every failure
a :class:`JsonFileError` naming the file, never a hang or a traceback) and writes it with
:func:`write_json_file` (atomically: a reader sees the old file or the new one).

:class:`FieldReader` lets a reader gather every problem of a file
(field, message) before it gives up, for one :class:`~.problems.ContractError` that lists them.

Standard library only.
"""
from __future__ import annotations

import json
import math
import os
from typing import Any, Callable, Sequence

from ..files import open_regular, write_json_atomic
from .problems import Problem

__all__ = ["FieldReader", "JsonFileError", "MAX_JSON_BYTES", "is_int", "is_number", "kind_of", "parse_json",
           "plain_json", "read_json_file", "read_text_file", "show_json", "write_json_file"]

#: Largest JSON file of a run folder read (run.json, summary.json): fourbar-run's run.json of a
#: mechanism with hundreds of parameters is tens of kB.
MAX_JSON_BYTES = 16 << 20


class JsonFileError(ValueError):
    """A JSON file of a run folder cannot be used: not JSON, nested too deeply, too large."""


def read_text_file(path: str | os.PathLike[str], *, max_bytes: int | None = None) -> str:
    """The UTF-8 text of the regular file ``path``, at most ``max_bytes`` long (default
    :data:`MAX_JSON_BYTES`).

    Raises ``FileNotFoundError``, :class:`~fourbar_common.files.NotRegularFileError`,
    :class:`JsonFileError` (too large, not UTF-8) naming the file, or ``OSError``.
    """
    if max_bytes is None:
        max_bytes = MAX_JSON_BYTES
    with open_regular(path) as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise JsonFileError(f"{path}: larger than {max_bytes} bytes; not a file fourbar-cosim writes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise JsonFileError(f"{path}: not UTF-8 text: {exc.reason} at byte {exc.start}") from None


def parse_json(text: str, source: str) -> Any:
    """``json.loads(text)`` with every failure a :class:`JsonFileError` naming ``source``:
    invalid JSON, and JSON nested deeper than Python's parser can follow (a RecursionError)."""
    try:
        return json.loads(text)
    except RecursionError:
        raise JsonFileError(f"{source}: JSON nested too deeply (arrays or objects inside each other more than "
                            "about a thousand levels); not a file fourbar-cosim writes") from None
    except ValueError as exc:
        raise JsonFileError(f"{source}: not valid JSON: {exc}") from None


def read_json_file(path: str | os.PathLike[str], *, max_bytes: int | None = None) -> Any:
    """The parsed JSON file ``path`` (regular, at most ``max_bytes``); errors as
    :func:`read_text_file` and :func:`parse_json`."""
    return parse_json(read_text_file(path, max_bytes=max_bytes), str(path))


def write_json_file(path: str | os.PathLike[str], data: Any, *, default: Callable[[Any], Any] | None = None) -> None:
    """Replace ``path`` by ``data`` as indented JSON, atomically (no NaN or infinity: they are
    not JSON; ``default`` converts what JSON has no type for)."""
    write_json_atomic(path, data, default=default)


def plain_json(data: Any, *, default: Callable[[Any], Any] | None = None) -> Any:
    """``data`` as the JSON file written from it reads back: tuples as lists, what JSON has no
    type for converted by ``default`` (ValueError for NaN or infinity, as when writing)."""
    return json.loads(json.dumps(data, allow_nan=False, default=default))


def show_json(value: Any, width: int = 60) -> str:
    """``value`` as JSON text for a message, cut to ``width`` characters."""
    try:
        text = json.dumps(value, allow_nan=True, default=str)
    except (RecursionError, ValueError):
        return f"<{kind_of(value)} nested too deeply to show>"
    return text if len(text) <= width else text[:width - 3] + "..."


def kind_of(value: Any) -> str:
    """What a JSON value is, for a message: ``null``, ``a number``, ``an object``, ..."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def is_number(value: Any) -> bool:
    """A finite JSON number (not a boolean)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def is_int(value: Any) -> bool:
    """A JSON integer (not a boolean)."""
    return isinstance(value, int) and not isinstance(value, bool)


_MISSING = object()


class FieldReader:
    """The fields of one JSON object, each checked; every problem is added to ``problems``
    (a :class:`~.problems.Problem` naming the dotted field) and the field reads as its default,
    so a reader sees every problem of a file before it raises one
    :class:`~.problems.ContractError`.

    A field absent from the object reads as its default: files written before it existed lack
    it.  A ``required`` field absent is a problem.
    """

    def __init__(self, data: Any, prefix: str, problems: list[Problem]):
        self.prefix = prefix
        self.problems = problems
        if isinstance(data, dict):
            self.data: dict = data
        else:
            self.data = {}
            self.problem(prefix.rstrip("."), f"{kind_of(data)}; expected a JSON object")

    def where(self, key: str | int) -> str:
        return f"{self.prefix}[{key}]" if isinstance(key, int) else f"{self.prefix}{key}"

    def problem(self, field: str, message: str) -> None:
        self.problems.append(Problem(field, message))

    def value(self, key: str, check: Callable[[Any], bool], expected: str, *, nullable: bool = False,
              required: bool = False, default: Any = None) -> Any:
        """The value of ``key`` when ``check`` accepts it (None when ``nullable``), else ``default``."""
        value = self.data.get(key, _MISSING)
        if value is _MISSING:
            if required:
                self.problem(self.where(key), f"missing: expected {expected}")
            return default
        if value is None and nullable:
            return None
        if not check(value):
            self.problem(self.where(key),
                         f"got {show_json(value)}, expected {expected}{' or null' if nullable else ''}")
            return default
        return value

    def schema(self, readable: Sequence[int]) -> int:
        """The file's ``schema`` (absent: the first of ``readable``, for files written before it
        was recorded); a schema not in ``readable`` is a problem (a newer one: update)."""
        schema = self.integer("schema", nullable=False, default=readable[0])
        if schema not in readable:
            self.problem(self.where("schema"), f"got {schema}: this reader reads schema "
                         f"{', '.join(map(str, readable))}" + ("; the file was written by a newer fourbar-cosim: "
                                                                "update this one" if schema > max(readable) else ""))
        return schema

    def number(self, key: str, *, nullable: bool = True, required: bool = False,
               default: float | None = None) -> float | None:
        """A finite number as written (an integer stays one, so a file reads back to its own bytes)."""
        return self.value(key, is_number, "a finite number", nullable=nullable, required=required, default=default)

    def integer(self, key: str, *, nullable: bool = True, required: bool = False,
                default: int | None = None) -> int | None:
        return self.value(key, is_int, "an integer", nullable=nullable, required=required, default=default)

    def text(self, key: str, *, nullable: bool = True, required: bool = False,
             default: str | None = None) -> str | None:
        return self.value(key, lambda v: isinstance(v, str), "a string", nullable=nullable, required=required,
                          default=default)

    def flag(self, key: str, *, nullable: bool = True, required: bool = False,
             default: bool | None = None) -> bool | None:
        return self.value(key, lambda v: isinstance(v, bool), "true or false", nullable=nullable,
                          required=required, default=default)

    def choice(self, key: str, choices: Sequence[str], *, nullable: bool = False, required: bool = False,
               default: str | None = None) -> str | None:
        return self.value(key, lambda v: v in choices, " | ".join(choices), nullable=nullable, required=required,
                          default=default)

    def texts(self, key: str, *, required: bool = False) -> tuple[str, ...]:
        return tuple(self.value(key, lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
                                "an array of strings", required=required, default=[]) or ())

    def numbers(self, key: str, *, length: int | None = None, nullable: bool = True,
                required: bool = False) -> tuple[float, ...] | None:
        expected = f"an array of {length} finite numbers" if length is not None else "an array of finite numbers"
        value = self.value(key, lambda v: isinstance(v, list) and all(is_number(x) for x in v)
                           and (length is None or len(v) == length), expected, nullable=nullable, required=required)
        return tuple(value) if value is not None else None

    def mapping(self, key: str, *, nullable: bool = True, required: bool = False) -> dict | None:
        """A JSON object kept as it is (a section whose keys belong to another part)."""
        return self.value(key, lambda v: isinstance(v, dict), "an object", nullable=nullable, required=required)

    def object(self, key: str, *, nullable: bool = True, required: bool = False) -> "FieldReader | None":
        """The object of ``key``, to read field by field; None when absent or null."""
        value = self.mapping(key, nullable=nullable, required=required)
        return None if value is None else FieldReader(value, f"{self.where(key)}.", self.problems)

    def array(self, key: str, *, required: bool = False) -> list:
        return self.value(key, lambda v: isinstance(v, list), "an array", required=required, default=[]) or []

    def objects(self, key: str, *, required: bool = False) -> list["FieldReader"]:
        """The objects of the array ``key``, each to read field by field (a non-object is a problem)."""
        return [FieldReader(item, f"{self.where(key)}[{i}].", self.problems)
                for i, item in enumerate(self.array(key, required=required))]
