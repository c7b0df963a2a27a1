"""Output folders on mount points and read-only places (issue 10, item 2)."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from popdispatch.report import output
from popdispatch.report.output import OutputError, check_writable, staged_folder


def _inside(path: str | os.PathLike, folder: Path) -> bool:
    return Path(os.path.abspath(path)).is_relative_to(folder.absolute())


@pytest.fixture
def mount_point(tmp_path, monkeypatch) -> Path:
    """An existing folder that behaves like a mount point: a rename into it from anywhere
    outside it fails with EXDEV, as ``os.rename`` does across file systems."""
    mount = tmp_path / "mnt"
    mount.mkdir()
    for name in ("rename", "replace"):
        real = getattr(os, name)

        def cross_device(src, dst, *args, _real=real, **kwargs):
            if _inside(dst, mount) != _inside(src, mount):
                raise OSError(errno.EXDEV, "Invalid cross-device link", str(src))
            return _real(src, dst, *args, **kwargs)

        monkeypatch.setattr(os, name, cross_device)
    return mount


def test_existing_folder_on_another_device_is_written(mount_point):
    (mount_point / "keep.txt").write_text("mine")
    with staged_folder(mount_point) as folder:
        folder.write_text("report.md", "new")
        folder.write_text("figures/a.png", "png")
    assert (mount_point / "report.md").read_text() == "new"
    assert (mount_point / "figures/a.png").read_text() == "png"
    assert (mount_point / "keep.txt").read_text() == "mine"  # an update, not a wipe
    assert sorted(p.name for p in mount_point.iterdir()) == ["figures", "keep.txt", "report.md"]
    assert [p.name for p in mount_point.parent.iterdir()] == ["mnt"]  # nothing staged outside


def test_new_folder_inside_a_mount_point_is_written(mount_point):
    with staged_folder(mount_point / "run") as folder:
        folder.write_text("summary.json", "{}")
    assert (mount_point / "run/summary.json").read_text() == "{}"
    assert [p.name for p in mount_point.iterdir()] == ["run"]


def test_staging_is_on_the_destinations_file_system(tmp_path, monkeypatch):
    made: list[str] = []
    real = tempfile.mkdtemp

    def record(*args, **kwargs):
        made.append(real(*args, **kwargs))
        return made[-1]

    monkeypatch.setattr(tempfile, "mkdtemp", record)
    existing, new = tmp_path / "existing", tmp_path / "new"
    existing.mkdir()
    with staged_folder(existing) as folder:
        folder.write_text("a.txt", "x")
    with staged_folder(new) as folder:
        folder.write_text("a.txt", "x")
    assert Path(made[0]).parent == existing.absolute()  # inside an existing folder
    assert Path(made[0]).name.startswith(".")  # hidden
    assert Path(made[1]).parent == tmp_path.absolute()  # a sibling of a new one
    assert Path(made[1]).name.startswith(".new.")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing", "new"]


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_existing_folder_is_unchanged_after_an_error(tmp_path, error):
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.md").write_text("old")
    with pytest.raises(error), staged_folder(out) as folder:
        folder.write_text("report.md", "half")
        raise error
    assert [p.name for p in out.iterdir()] == ["report.md"]  # no staging folder left
    assert (out / "report.md").read_text() == "old"


def test_a_mount_point_below_the_output_folder_is_copied_then_renamed(tmp_path, monkeypatch):
    out = tmp_path / "out"
    (out / "figures").mkdir(parents=True)
    real = os.replace

    def figures_elsewhere(src, dst, *args, **kwargs):
        if Path(dst).parent.name == "figures" and Path(src).parent.name != "figures":
            raise OSError(errno.EXDEV, "Invalid cross-device link", str(src))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", figures_elsewhere)
    with staged_folder(out) as folder:
        folder.write_text("figures/a.png", "png")
    assert (out / "figures/a.png").read_text() == "png"
    assert [p.name for p in (out / "figures").iterdir()] == ["a.png"]


# -- read-only places ------------------------------------------------------------------------


def _refuse(code: int):
    def refuse(*args, **kwargs):
        raise OSError(code, os.strerror(code), kwargs.get("dir"))

    return refuse


@pytest.mark.parametrize(
    ("code", "words"),
    [(errno.EROFS, "read-only file system"), (errno.EACCES, "permission denied")],
)
@pytest.mark.parametrize("exists", [True, False])
def test_unwritable_folder_is_named_in_one_line(tmp_path, monkeypatch, code, words, exists):
    out = tmp_path / "out"
    if exists:
        out.mkdir()
    monkeypatch.setattr(tempfile, "mkdtemp", _refuse(code))
    for attempt in (lambda: check_writable(out), lambda: staged_folder(out).__enter__()):
        with pytest.raises(OutputError) as caught:
            attempt()
        assert str(caught.value) == f"cannot write to {out}: {words}"
        assert caught.value.errno == code


def test_a_write_refused_midway_is_reported_and_cleaned_up(tmp_path, monkeypatch):
    out = tmp_path / "out"

    def refuse(self, *args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", str(self))

    message = r"^cannot write to .*out: read-only file system$"
    with pytest.raises(OutputError, match=message), staged_folder(out) as folder:
        monkeypatch.setattr(Path, "write_text", refuse)
        folder.write_text("report.md", "x")
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []


def test_other_errors_are_not_called_read_only(tmp_path):
    with pytest.raises(FileNotFoundError), staged_folder(tmp_path / "out"):
        open(tmp_path / "missing" / "x")  # noqa: SIM115


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a chmod 0o555 folder anyway")
def test_chmod_read_only_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    out.chmod(0o555)
    try:
        with pytest.raises(OutputError, match="permission denied"):
            check_writable(out)
    finally:
        out.chmod(0o755)


def test_atomic_write_names_a_read_only_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "mkstemp", _refuse(errno.EROFS))
    with pytest.raises(OutputError, match="read-only file system"):
        output.atomic_write_text(tmp_path / "f.txt", "x")


# -- the command line, in subprocesses --------------------------------------------------------

#: Runs ``popdispatch`` with the renames or staging of this process patched as described.
CLI = """
import errno, os, sys, tempfile
from pathlib import Path
mode, out = sys.argv[1], Path(sys.argv[2]).absolute()
if mode == "read-only":
    def refuse(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", kwargs.get("dir"))
    tempfile.mkdtemp = refuse
else:  # ``out`` behaves like a mount point: renames into it from outside fail
    for name in ("rename", "replace"):
        def cross(src, dst, *a, _real=getattr(os, name), **k):
            inside = lambda p: Path(os.path.abspath(p)).is_relative_to(out)
            if inside(src) != inside(dst):
                raise OSError(errno.EXDEV, "Invalid cross-device link", str(src))
            return _real(src, dst, *a, **k)
        setattr(os, name, cross)
from popdispatch.cli import main
sys.exit(main(["snapshot", "--minute", "566", "--out", str(out), "--quiet"]))
"""


def _cli(mode: str, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", CLI, mode, str(out)], capture_output=True, text=True, timeout=600
    )


def test_cli_writes_into_a_mount_point(tmp_path):
    out = tmp_path / "mnt"
    out.mkdir()
    result = _cli("mount-point", out)
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "setpoints.pdf",
        "setpoints.png",
        "summary.json",
        "trajectory.csv",
    ]


def test_cli_says_read_only_in_one_line(tmp_path):
    out = tmp_path / "out"
    result = _cli("read-only", out)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert lines[-1] == f"popdispatch: error: cannot write to {out}: read-only file system"
    assert "Errno" not in result.stderr and "cross-device" not in result.stderr
