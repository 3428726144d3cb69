"""Files replaced atomically: a reader sees the old content or the new, never a mixture."""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Callable

__all__ = ["replace_atomically", "write_json_atomic"]


def replace_atomically(path: str | os.PathLike[str], write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a fresh temporary path beside ``path``, then rename it over ``path``.

    The temporary name is unique (``tempfile.mkstemp``), so concurrent writers of the same
    file never share one; on any failure the temporary file is removed and ``path`` is
    left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_json_atomic(path: str | os.PathLike[str], data: Any, *, default: Callable[[Any], Any] | None = None) -> None:
    """Replace ``path`` by ``data`` as indented JSON (no NaN or infinity: they are not JSON)."""
    text = json.dumps(data, indent=2, allow_nan=False, default=default) + "\n"

    def write(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)

    replace_atomically(path, write)

