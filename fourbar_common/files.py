"""Files replaced atomically (a reader sees the old content or the new, never a mixture), and
files opened for reading only when they are regular files (a FIFO or a device never blocks a reader)."""
from __future__ import annotations

import errno
import json
import os
import secrets
import stat
from pathlib import Path
from typing import Any, BinaryIO, Callable

__all__ = ["NotRegularFileError", "file_kind", "open_regular", "output_folder_problem", "replace_atomically",
           "write_json_atomic"]

#: Mode asked for a new file, as ``open(path, "w")`` does; the process umask removes bits
#: from it (usually 0o022, giving 0o644: readable by others, like exchange.csv and plots).
_FILE_MODE = 0o666


def _create_unique(directory: Path, prefix: str, suffix: str) -> Path:
    """Create a new, empty file with a unique name in ``directory`` and return its path.

    Like ``tempfile.mkstemp`` (``O_EXCL``: two writers never share a name), but created
    with mode 0o666 minus the umask as an ordinary file, where mkstemp gives 0o600 and
    the renamed file would be readable by its owner only.
    """
    for _ in range(100):
        candidate = directory / f"{prefix}{secrets.token_hex(6)}{suffix}"
        try:
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, _FILE_MODE)
        except FileExistsError:
            continue
        os.close(fd)
        return candidate
    raise FileExistsError(f"no unused temporary name {prefix}*{suffix} in {directory}")


def replace_atomically(path: str | os.PathLike[str], write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a fresh temporary path beside ``path``, then rename it over ``path``.

    The temporary name is unique (created with ``O_EXCL``), so concurrent writers of the
    same file never share one; on any failure the temporary file is removed and ``path`` is
    left as it was.  The new file's mode is that of a file ``open(path, "w")`` creates
    (0o666 minus the process umask), whether ``write`` writes into the temporary file or
    replaces it.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _create_unique(path.parent, f".{path.name}.", ".tmp")
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


def output_folder_problem(out: str | os.PathLike[str], receives: str) -> str | None:
    """Why folder ``out`` cannot take a command's outputs, as the end of a message naming it
    (``--out OUT: ...``), or None when it can: it is a file, a parent on its way is a file, or
    the nearest existing folder cannot be written.  ``receives`` says what the folder is for.
    Creates nothing."""
    out = Path(out)
    try:
        if out.exists() and not out.is_dir():
            return f"exists and is not a folder; --out names the folder that receives {receives}"
        parent = out
        while not parent.exists() and parent.parent != parent:
            parent = parent.parent
        if not parent.is_dir():
            return f"{parent} is not a folder, so the output folder cannot be made there"
        if not os.access(parent, os.W_OK | os.X_OK):
            return f"{parent} is not writable; choose a writable folder with --out"
    except OSError as exc:
        return str(exc.strerror or exc)
    return None


class NotRegularFileError(OSError):
    """A path names a FIFO, a device, a socket or a directory where a file was expected."""

    def __str__(self) -> str:
        return self.strerror or super().__str__()


def file_kind(mode: int) -> str:
    """``is a FIFO``, ``is a directory``, ... for a file mode that is not a regular file's."""
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return f"is {name}"
    return "is not a regular file"


def open_regular(path: str | os.PathLike[str]) -> BinaryIO:
    """Open ``path`` for reading in binary mode, refusing what is not a regular file.

    The file is opened with ``O_NONBLOCK`` (so a FIFO without a writer does not block the
    reader) and checked with ``fstat`` on the open descriptor (no race between a check and
    the open); blocking mode is restored for a regular file.  Raises
    :class:`NotRegularFileError` naming the path and what it is, ``FileNotFoundError`` when
    there is none, other ``OSError`` as ``open`` does.
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except IsADirectoryError:
        raise NotRegularFileError(errno.EISDIR, f"{path}: is a directory, not a regular file") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegularFileError(errno.EINVAL, f"{path}: {file_kind(mode)}, not a regular file")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
