"""The one exception a user mistake raises: :class:`DiagnoseError` (the command exits 2)."""
from __future__ import annotations

__all__ = ["DiagnoseError", "NoAlarm"]


class DiagnoseError(Exception):
    """Bad input: the message names the file or option and what to do."""


class NoAlarm(DiagnoseError):
    """The monitor raised no alarm in this run: there is no fault to classify."""
