"""Text from a mechanism file made safe to quote in generated source code.

A mechanism's description and its file's name are written into the generated code: a C block
comment of equations.h, the docstrings of the pythonfmu script and of the equations module.  A
description holding ``*/`` or ``\"\"\"`` would end the comment or the docstring and put the rest of
the text into the code (``description = 'x\"\"\"; import os; os.system(\"id\") #'`` ran when the
FMU loaded).  :func:`comment_text` removes what can end either: control characters (newlines
included), backslashes (a backslash-newline splices C lines before comments are read), double
quotes, ``*/`` and ``/*``, and ``??`` (C99 trigraphs: ``??/`` is a backslash).  Text that has
none of these is returned unchanged, so the shipped mechanisms' sources are the same.
"""
from __future__ import annotations

__all__ = ["comment_text"]

_BROKEN = (("*/", "* /"), ("/*", "/ *"), ("??", "? ?"))


def comment_text(text: str) -> str:
    """``text`` as it may stand inside a C ``/* */`` comment or a Python triple-quoted docstring."""
    out = "".join(c if c.isprintable() else " " for c in str(text)).replace("\\", "/").replace('"', "'")
    changed = True
    while changed:
        changed = False
        for seq, fix in _BROKEN:
            if seq in out:
                out, changed = out.replace(seq, fix), True
    return out
