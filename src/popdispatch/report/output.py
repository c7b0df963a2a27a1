"""Writing results without ever leaving a half-written file.

Every file is first written under a temporary name in its final folder and then renamed (an
atomic operation on one file system). A whole output folder is staged the same way: files go
into a hidden temporary folder next to it, and only when everything is written are they moved
into place. An error or Ctrl-C removes the staging folder, so ``--out`` never holds partial
files.
"""

from __future__ import annotations

import contextlib
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

    Files are written into a hidden sibling folder of ``out``; each is renamed into ``out`` only
    after all were written. On an error or Ctrl-C the staging folder is removed and ``out`` is
    left as it was.
    """
    out = Path(out)
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise OSError(f"cannot write to {out}: folder {parent} does not exist")
    if out.exists() and not out.is_dir():
        raise OSError(f"cannot write to {out}: it exists and is not a folder")
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent))
    try:
        yield StagedFolder(staging)
        _move_into(staging, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _move_into(staging: Path, out: Path) -> None:
    """Move the staged files into ``out``: one rename of the folder if ``out`` is new."""
    if not out.exists():
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes 0700
        os.replace(staging, out)
        return
    for source in sorted(p for p in staging.rglob("*") if p.is_file()):
        target = out / source.relative_to(staging)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(source, target)
