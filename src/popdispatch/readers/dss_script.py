"""OpenDSS scripts compiled in place, statement by statement, as OpenDSS reads them.

:func:`compiled_script` runs a master file or a run script (``Run_8500Node.dss``: ``Compile
(master.dss)``, then edits, ``Solve``, ``Show``, ``Plot``, ``Export``) in a private
OpenDSSDirect.py context. popdispatch reads each file itself and hands OpenDSS one statement
at a time, so that:

- **File names are found as Windows finds them.** ``Compile``/``Redirect`` targets, ``BusCoords``
  files and the ``file=``, ``csvfile=``, ``sngfile=``, ``dblfile=`` values of load shapes and
  curves are looked up relative to the folder OpenDSS would use (the folder of the file being
  read; a ``Compile`` moves it to the compiled file's folder for the rest of the script, a
  ``Redirect`` only while its file is read), ignoring case and with ``\\`` as a separator,
  and handed to OpenDSS as absolute paths. The files themselves are never copied or changed.
- **The script's edits are honoured.** Every statement that defines or changes the circuit
  (``New``, ``Edit``, ``~``, ``Open``, ``Close``, ``Enable``, ``Disable``, ``Set``,
  ``BatchEdit``, ``Class.Name.Property=value``, ``CalcVoltageBases``, ...) is run in the order
  of the script, also after the ``Compile``.
- **Commands that only solve, show, plot or export are skipped**, with no side effect:
  ``Solve``, ``Show``, ``Plot``, ``Export``, ``Summary``, ``Visualize``, ``CloseDI``,
  ``Interpolate`` and every other command of OpenDSS's list that neither defines nor changes the
  circuit (:data:`PASSED` lists those that do). No viewer is opened (``AllowForms`` off), and
  OpenDSS's data folder (where ``Set Demand=true`` or ``Set CaseName`` create folders) is a
  private temporary folder, removed afterwards.
- **A missing ``Redirect``/``Compile`` target** is skipped with a note naming the file and line,
  as OpenDSS does (its error 243 stops a solution, not the script).
- **Any statement OpenDSS refuses** raises :class:`~popdispatch.errors.FeederError`: one line
  naming the file, the line, the statement and OpenDSS's message (which names the element).

Block comments (a line starting ``/*`` up to the line holding ``*/``), ``!`` and ``//``
comments and command abbreviations (``redir``, ``sol``) are read as OpenDSS reads them.
"""

from __future__ import annotations

import contextlib
import re
import tempfile
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from popdispatch.errors import FeederError
from popdispatch.readers.opendss import find_file

_EXTRA = "pip install popdispatch[opendss]"

#: OpenDSS commands that define or change the circuit: run as they are.
PASSED = frozenset({
    "new", "edit", "more", "m", "~", "select", "enable", "disable", "set", "open", "close",
    "clear", "clearall", "calcvoltagebases", "setkvbase", "makebuslist", "makeposseq",
    "reconductor", "setloadandgenkv", "variable", "var", "connect", "disconnect", "remove",
    "batchedit", "setbusxy", "reprocessbuses", "rephase", "like",
})  # fmt: skip
#: Commands that read a file named by their first argument, resolved here.
FILE_COMMANDS = frozenset({"compile", "redirect"})
COORDINATE_COMMANDS = frozenset({"buscoords", "latlongcoords"})
#: Commands after which OpenDSS's data folder is checked (they may move it).
_MOVES_DATA_PATH = frozenset({"set", "clear", "clearall"})

_FILE_KEY = re.compile(
    r"""(\b(?:csv|sng|dbl)?file\s*=\s*)("[^"]*"|'[^']*'|[^\s)\],]+)""", re.IGNORECASE
)
_SPECIAL = re.compile(r"!|//|[\"'(\[{]")
_FIRST_WORD = re.compile(r"\s*([^\s=,]+)")
_NEW_TARGET = re.compile(r"\s*\S+\s+(?:object\s*=\s*)?([^\s=,]+\.[^\s=,]+)", re.IGNORECASE)


def opendss():
    """The ``opendssdirect`` module, or a clear error naming the extra."""
    try:
        import opendssdirect
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"reading OpenDSS files needs OpenDSSDirect.py: {_EXTRA} ({exc})"
        ) from exc
    return opendssdirect


@dataclass
class Script:
    """A compiled script: its OpenDSS ``ctx`` and what was skipped or noted on the way.

    ``skipped``: commands not run (solve, show, plot, ...) with how often; ``notes``: one line
    each (a missing file skipped).
    """

    ctx: object
    path: Path
    skipped: Counter = field(default_factory=Counter)
    notes: list[str] = field(default_factory=list)
    defined: dict[str, tuple[Path, int]] = field(default_factory=dict)

    def where(self, element: str) -> str:
        """``file:line`` of the ``New`` statement that defined ``element`` (``Line.x``, case
        ignored), else the script's path."""
        found = self.defined.get(element.lower())
        return f"{found[0]}:{found[1]}" if found else str(self.path)

    def summary(self) -> str:
        """The notes in one line ('' when there are none). The skipped commands change nothing
        that is read, so they are not among them (:attr:`skipped` lists them)."""
        parts = list(self.notes[:3])
        if len(self.notes) > 3:
            parts.append(f"and {len(self.notes) - 3} more like them")
        return "; ".join(parts)


@contextlib.contextmanager
def compiled_script(path: str | Path) -> Iterator[Script]:
    """Compile the OpenDSS script ``path`` in a new context (see the module docstring) and
    yield it as a :class:`Script`; the context is cleared and its data folder removed after."""
    path = Path(path)
    if not path.is_file():
        raise FeederError(f"OpenDSS file {path} does not exist")
    with tempfile.TemporaryDirectory(prefix="popdispatch-dss-") as scratch:
        try:
            script = _compile(path, Path(scratch), batched=True)
        except _BatchFailed:  # run again one statement at a time to name the one refused
            script = _compile(path, Path(scratch), batched=False)
        try:
            yield script
        finally:
            with contextlib.suppress(Exception):
                script.ctx.Text.Command("clearall")


class _BatchFailed(Exception):
    """OpenDSS refused a statement of a batch (which one, a statement-by-statement run tells)."""


def _compile(path: Path, scratch: Path, batched: bool) -> Script:
    """A new context with ``path`` compiled into it; ``batched``: consecutive statements are
    handed to OpenDSS together (faster; a refusal raises :class:`_BatchFailed`)."""
    ctx = opendss().NewContext()
    ctx.Basic.AllowChangeDir(False)  # keep the process's working directory
    ctx.Basic.AllowForms(False)  # no viewer, no message box
    ctx.Basic.AllowEditor(False)
    script = Script(ctx, path)
    runner = _Runner(script, scratch, _command_names(ctx), batched)
    try:
        runner.run_file(path.resolve(), is_compile=True)
        runner.flush()
    except BaseException:
        with contextlib.suppress(Exception):
            ctx.Text.Command("clearall")
        raise
    return script


def _command_names(ctx) -> list[str]:
    """OpenDSS's executive commands, lower case, in its own order (abbreviations resolve to
    the first command that starts with them, as OpenDSS does)."""
    count = ctx.Executive.NumCommands()
    return [ctx.Executive.Command(i).lower() for i in range(1, count + 1)]


def statements(path: Path) -> Iterator[tuple[int, str]]:
    """``(line number, text)`` of every statement of an OpenDSS file: blank lines, comment
    lines and block comments left out (inline comments are OpenDSS's to read)."""
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as exc:
        raise FeederError(f"cannot read OpenDSS file {path}: {exc}") from None
    in_block = False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if in_block:
            in_block = "*/" not in line
            continue
        if line.startswith("/*"):
            in_block = "*/" not in line[2:]
            continue
        if line and not line.startswith(("!", "//")):
            yield number, line


def strip_comment(text: str) -> str:
    """``text`` up to an ``!`` or ``//`` comment outside quotes and brackets."""
    first = _SPECIAL.search(text)
    if first is None:
        return text.rstrip()
    if first.group() in ("!", "//"):
        return text[: first.start()].rstrip()
    closing = {'"': '"', "'": "'", "(": ")", "[": "]", "{": "}"}
    stack: list[str] = []
    i = 0
    while i < len(text):
        ch = text[i]
        if stack and ch == stack[-1]:
            stack.pop()
        elif stack and stack[-1] in "\"'":
            pass
        elif ch in closing:
            stack.append(closing[ch])
        elif not stack and (ch == "!" or text.startswith("//", i)):
            return text[:i].rstrip()
        i += 1
    return text.rstrip()


def first_argument(text: str) -> str:
    """The value of a command's first argument: ``Compile (master.dss)`` -> ``master.dss``,
    also quoted (``"..."``, ``'...'``) or bracketed, or named (``file=...``)."""
    rest = _FIRST_WORD.sub("", text, count=1).strip()
    rest = re.sub(r"^\w+\s*=\s*", "", rest)  # file=..., filename=...
    if rest[:1] in "\"'([{":
        close = {'"': '"', "'": "'", "(": ")", "[": "]", "{": "}"}[rest[0]]
        end = rest.find(close, 1)
        return rest[1 : end if end > 0 else None].strip()
    return rest.split()[0] if rest else ""


class _Runner:
    """Reads files statement by statement into the script's context."""

    def __init__(
        self, script: Script, scratch: Path, commands: list[str], batched: bool = True
    ) -> None:
        self.script = script
        self.ctx = script.ctx
        self.scratch = scratch
        self.commands = commands
        self.folder = script.path.resolve().parent
        self.depth = 0
        self.batched = batched
        self.pending: list[str] = []
        self._data_path()

    def _data_path(self) -> None:
        """Keep OpenDSS's data folder (where it writes reports) in the scratch folder."""
        if Path(self.ctx.Basic.DataPath() or ".").resolve() != self.scratch.resolve():
            self.ctx.Basic.DataPath(str(self.scratch))

    def command(self, word: str) -> str | None:
        """The OpenDSS command a statement's first word names, or None (a property
        assignment ``Class.Name.Property=value`` or an unknown word)."""
        word = word.lower()
        if word in self.commands:
            return word
        return next((c for c in self.commands if c.startswith(word)), None)

    def run_file(self, path: Path, is_compile: bool) -> None:
        self.depth += 1
        if self.depth > 50:
            raise FeederError(f"{path}: files redirect to each other more than 50 deep")
        saved = self.folder
        self.folder = path.parent
        for number, text in statements(path):
            self.statement(path, number, text)
        if not is_compile:
            self.folder = saved
        self.depth -= 1

    def statement(self, path: Path, number: int, text: str) -> None:
        code = strip_comment(text)
        match = _FIRST_WORD.match(code)
        if not code or match is None:
            return
        word = match.group(1)
        command = self.command(word) if "." not in word else None
        if command == "//":
            return
        if command in FILE_COMMANDS:
            target = self.resolve(first_argument(code), path, number, add_dss=True)
            if target is None:
                missing = first_argument(code)
                self.script.notes.append(
                    f"{path.name}:{number}: {command} of a missing file {missing!r} skipped "
                    "(OpenDSS error 243)"
                )
                return
            self.flush()
            self.run_file(target, command == "compile")
            return
        if command == "cd":
            found = self.resolve(first_argument(code), path, number, folder=True)
            if found is None:
                raise FeederError(f"{path}:{number}: no such folder: {text!r}")
            self.folder = found
            return
        if command in COORDINATE_COMMANDS:
            target = self.resolve(first_argument(code), path, number)
            if target is None:  # coordinates only place the buses on the figures
                self.script.notes.append(
                    f"{path.name}:{number}: {command} of a missing file "
                    f"{first_argument(code)!r} skipped: the buses have no coordinates"
                )
                return
            self.send(path, number, text, f'{command} "{target}"')
            self.flush()
            return
        if command is not None and command not in PASSED:
            self.script.skipped[command] += 1
            return
        if command == "new":
            target = _NEW_TARGET.match(code)
            if target:
                self.script.defined[target.group(1).lower()] = (path, number)
        if "ile" in code or "ILE" in code:
            code = _FILE_KEY.sub(lambda m: self.file_value(m, path), code)
        self.send(path, number, text, code)
        if command in _MOVES_DATA_PATH:
            self.flush()
            self._data_path()

    def send(self, path: Path, number: int, text: str, code: str) -> None:
        if self.batched:
            self.pending.append(code)
            if len(self.pending) >= 2000:
                self.flush()
            return
        try:
            self.ctx.Text.Command(code)
        except Exception as exc:  # DSSException; its class lives in dss-python
            message = " ".join(str(exc).split())
            raise FeederError(f"{path}:{number}: OpenDSS: {message}: {text!r}") from None

    def flush(self) -> None:
        """Hand the pending statements to OpenDSS in one call."""
        if not self.pending:
            return
        batch, self.pending = self.pending, []
        try:
            self.ctx.Text.Commands(batch)
        except Exception:  # DSSException: which statement, the unbatched run tells
            raise _BatchFailed from None

    def file_value(self, match: re.Match, path: Path) -> str:
        """A ``file=`` value as an absolute path where the file is found (else unchanged:
        OpenDSS then names the missing file)."""
        found = self.resolve(match.group(2), path, None)
        return match.group(0) if found is None else f'{match.group(1)}"{found}"'

    def resolve(
        self, raw: str, path: Path, number: int | None, add_dss: bool = False,
        folder: bool = False,
    ) -> Path | None:  # fmt: skip
        """The file (or ``folder``) ``raw`` names, from the current folder, case ignored and
        ``\\`` read as ``/``; ``add_dss``: try ``.dss`` appended to a name without a suffix (as
        OpenDSS does for ``Redirect``)."""
        name = raw.strip().strip("\"'")
        if not name:
            return None
        candidates = [name]
        if add_dss and "." not in Path(name.replace("\\", "/")).name:
            candidates.append(name + ".dss")
        for candidate in candidates:
            absolute = candidate.replace("\\", "/").startswith("/")
            try:
                found = find_file(Path("/") if absolute else self.folder, candidate)
            except FeederError as exc:
                raise FeederError(f"{path}:{number}: {exc}") from None
            if found is not None and (found.is_dir() if folder else found.is_file()):
                return found.resolve()
        return None


__all__ = ["PASSED", "Script", "compiled_script", "first_argument", "statements", "strip_comment"]
