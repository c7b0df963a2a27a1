"""Writing results without ever leaving a half-written file.

Every file is first written under a temporary name in its final folder and then renamed (an
atomic operation on one file system). A whole output folder is staged the same way: files go
into a hidden temporary folder on the same file system as their destination (next to a new
folder, inside an existing one, so a mount point works), and only when everything is written
are they moved into place. An error or Ctrl-C removes the staging folder, so ``--out`` never
holds partial files. A folder that cannot be written gives a one-line :class:`OutputError`
("read-only file system", "permission denied").
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy and pandas are imported where used: the CLI imports this module
    import pandas as pd


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` to create a file at a temporary path, then rename it to ``path``.

    The temporary file is in ``path``'s folder (same file system); it is removed on any error
    or interruption. Returns ``path``.
    """
    path = Path(path)
    with _output_errors(path, creating=True):
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{path.name}.", suffix=".tmp" + path.suffix, dir=path.parent
        )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def to_jsonable(value):
    """Numpy scalars and arrays to plain Python; NaN and infinities to ``None``."""
    import numpy as np
    import pandas as pd

    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray | pd.Index):
        return [to_jsonable(v) for v in list(value)]
    if isinstance(value, np.bool_ | bool):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else None
    return value


def json_text(summary: dict) -> str:
    """The JSON text of a summary object (strict JSON: no NaN)."""
    return json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n"


class StagedFolder:
    """Files being written for an output folder; see :func:`staged_folder`."""

    def __init__(self, staging: Path):
        self.path = staging

    def file(self, name: str) -> Path:
        """Path of ``name`` inside the staging folder (parent folders are created)."""
        target = self.path / name
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def write_text(self, name: str, text: str) -> None:
        self.file(name).write_text(text, encoding="utf-8")

    def write_json(self, name: str, summary: dict) -> None:
        self.write_text(name, json_text(summary))

    def write_csv(self, name: str, table: pd.DataFrame) -> None:
        table.to_csv(self.file(name), index=False, float_format="%.10g")


@contextlib.contextmanager
def staged_folder(out: str | Path) -> Iterator[StagedFolder]:
    """Stage an output folder; on success move every file into ``out`` (created if needed).

    Where the files are staged decides whether the final renames stay on one file system:

    - ``out`` does not exist: a hidden sibling ``.NAME.tmp-XXXX`` in ``out``'s parent (where
      ``out`` will be), renamed to ``out`` in one step when everything is written.
    - ``out`` is an existing folder (possibly a mount point: a tmpfs, a Docker volume, a network
      share, whose parent is on another device): a hidden ``.popdispatch-tmp-XXXX`` folder
      *inside* ``out``. Each file is then renamed over its namesake in ``out``; files of
      ``out`` that this run does not write are left untouched (the folder is updated, not
      emptied).

    On an error or Ctrl-C before the moves the staging folder is removed and ``out`` is left as
    it was. A folder that cannot be written raises :class:`OutputError` with a one-line message
    naming the path and the reason ("read-only file system", "permission denied").
    """
    out = Path(out)
    check_target(out)
    inside = out.is_dir()
    staging = _make_staging(out)
    try:
        with _output_errors(out):
            yield StagedFolder(staging)
            _move_into(staging, out, inside)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


class OutputError(OSError):
    """An output folder that cannot be written; ``str()`` is a one-line message."""

    def __str__(self) -> str:
        return self.strerror or super().__str__()


#: errno values that mean "this place cannot be written", with the words we report them in.
NOT_WRITABLE = {
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
}


def missing_folder(out: str | Path) -> str | None:
    """Why ``out``'s folder is not there (``folder F does not exist``, or ``F is a file, not a
    folder`` for the first part of the path that is a file), None where it is."""
    parent = Path(out).absolute().parent
    if parent.is_dir():
        return None
    for part in (parent, *parent.parents):
        if part.exists():
            if not part.is_dir():
                return f"{part} is a file, not a folder"
            break
    return f"folder {parent} does not exist"


def check_target(out: Path) -> None:
    """Raise :class:`OutputError` unless ``out`` is, or can become, a folder."""
    missing = missing_folder(out)
    if missing is not None:
        raise OutputError(f"cannot write to {out}: {missing}")
    if out.exists() and not out.is_dir():
        raise OutputError(f"cannot write to {out}: it exists and is not a folder")


def check_writable(out: str | Path) -> None:
    """Fail early (before any long computation) if ``out`` could not be written.

    Creates and removes the staging folder :func:`staged_folder` would use; raises
    :class:`OutputError` (one line, "read-only file system" / "permission denied").
    """
    out = Path(out)
    check_target(out)
    shutil.rmtree(_make_staging(out), ignore_errors=True)


def _make_staging(out: Path) -> Path:
    """The staging folder for ``out`` (see :func:`staged_folder`), created empty."""
    if out.is_dir():
        where, prefix = out, ".popdispatch-tmp-"
    else:
        where, prefix = (out.parent if str(out.parent) else Path(".")), f".{out.name}.tmp-"
    with _output_errors(out, creating=True):
        return Path(tempfile.mkdtemp(prefix=prefix, dir=where))


@contextlib.contextmanager
def _output_errors(out: Path, creating: bool = False) -> Iterator[None]:
    """Turn "cannot write here" errors into one-line :class:`OutputError` naming ``out`` and
    the reason, never a temporary name. ``creating``: the block only creates the staging file
    or folder, so any error there means the place takes no new files (a pseudo file system
    such as ``/proc`` says "no such file or directory"); elsewhere other errors pass."""
    try:
        yield
    except OutputError:
        raise
    except OSError as exc:
        reason = NOT_WRITABLE.get(exc.errno)
        if reason is None and not creating:
            raise
        if reason is None:
            folder = out if out.is_dir() else (out.parent if str(out.parent) else Path("."))
            reason = f"{folder} does not take new files ({(exc.strerror or str(exc)).lower()})"
        raise OutputError(exc.errno, f"cannot write to {out}: {reason}") from exc


def _move_into(staging: Path, out: Path, inside: bool) -> None:
    """Move the staged files into ``out``: one rename of the folder if ``out`` is new
    (``inside``: the staging folder is inside an existing ``out``)."""
    if not inside:
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes 0700
        try:
            os.rename(staging, out)  # fails if ``out`` appeared meanwhile: then merge
            return
        except OSError:
            if not out.is_dir():
                raise
    for source in sorted(p for p in staging.rglob("*") if p.is_file()):
        target = out / source.relative_to(staging)
        target.parent.mkdir(parents=True, exist_ok=True)
        _replace(source, target)


def _replace(source: Path, target: Path) -> None:
    """``os.replace``; if ``target``'s folder is another file system (a mount point inside
    ``out``), copy next to ``target`` first so the final step is still one rename."""
    try:
        os.replace(source, target)
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
        atomic_write(target, lambda tmp: shutil.copyfile(source, tmp))
