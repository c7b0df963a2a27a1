"""A small, strict reader of MATPOWER case files (``.m``) into a radial :class:`Feeder`.

MATPOWER cases are MATLAB functions. Besides the data matrices, the radial distribution cases
(``case22``, ``case33bw``, ``case69``, ``case85``, ...) state loads in kW and impedances in ohm
and convert them with MATLAB statements *after* the matrices, e.g.::

    Vbase = mpc.bus(1, BASE_KV) * 1e3;      %% in Volts
    Sbase = mpc.baseMVA * 1e6;              %% in VA
    mpc.branch(:, [BR_R BR_X]) = mpc.branch(:, [BR_R BR_X]) / (Vbase^2 / Sbase);
    mpc.bus(:, [PD, QD]) = mpc.bus(:, [PD, QD]) / 1e3;

A reader that only takes the matrices is off by a factor of 1000 (pandapower's ``from_mpc``
does exactly that: pandapower issue #2403). This reader interprets the file statement by
statement, in order, with a tiny evaluator (no Python ``eval`` of file text). It understands:

- ``function mpc = NAME``, ``mpc.version = '2'``;
- ``mpc.baseMVA = EXPR``; ``mpc.bus``, ``mpc.gen``, ``mpc.branch``, ``mpc.gencost`` and
  ``mpc.areas`` ``= [ ... ]`` matrices (rows separated by ``;`` or new lines, elements by
  blanks or commas); the cell arrays ``mpc.bus_name``, ``mpc.gentype``, ``mpc.genfuel`` are
  skipped (names only);
- MATPOWER's column names: ``define_constants`` and ``[PQ, PV, ...] = idx_bus`` (``idx_brch``,
  ``idx_gen``, ``idx_cost``), assigned by position as MATLAB does;
- scalar assignments ``NAME = EXPR``;
- assignments to blocks of a matrix, ``mpc.X(ROWS, COLS) = EXPR``, where ``ROWS``/``COLS`` are
  ``:``, a number, a name or a vector ``[C1 C2]`` (1-based, within the matrix);
- expressions of numbers, named scalars, ``mpc.baseMVA``, blocks ``mpc.X(ROWS, COLS)``,
  ``Inf``, ``pi``, ``+ - * / ^`` (and ``.* ./ .^``; ``*``, ``/`` and ``^`` need a scalar operand
  where MATLAB would do matrix algebra), unary signs, parentheses, ``[...]`` vectors and the
  functions ``sqrt abs exp log log10 sin cos tan asin acos atan``.

Comments (``%``, ``%{ ... %}`` blocks), ``...`` continuations and ``;`` are handled. Any other
statement raises :class:`~popdispatch.errors.FeederError` naming the file, the line and the
statement; so do unsupported elements (phase shifters, shunt conductance).

Conversion to the :class:`Feeder` (kW, ohm, km):

- buses: the non-isolated buses by their MATPOWER numbers (an isolated bus, ``BUS_TYPE`` 4, is
  dropped with its load and generators, as MATPOWER does; an in-service branch to one is an
  error). Shunt conductance ``GS`` (a constant demand in MATPOWER's DC model) is refused.
  MATPOWER has no coordinates: ``x``/``y`` are a schematic layout of the tree (``x`` = hops
  from the source, ``y`` = number of leaves before the bus in depth-first order), not
  geography. ``vn_kv`` is the bus's ``baseKV``.
- source bus: the reference bus (``BUS_TYPE`` 3), or ``root``. Several reference buses in
  separate trees are several feeders (MATPOWER's ``case16ci``: three feeders, ties open),
  joined for one run at a virtual bus by balance lines of 0 kW, so that each is balanced by
  its own generators (:mod:`popdispatch.feeder.radial`); ``root`` picks one of them instead
  (the parts not connected to it are dropped). Several reference buses in one tree are refused.
  Without ``root``, a part connected to no source is dropped only when it has no load (else
  the feeder's disconnected error).
- lines: the in-service branches (``BR_STATUS`` not 0; tie lines are out of service and are
  not part of the feeder), named ``L<from>-<to>`` (``#<row>`` appended on a repeated pair).
  ``r_ohm``/``x_ohm`` = p.u. value x ``Z_base`` with ``Z_base = baseKV^2 / baseMVA`` (ohm),
  ``baseKV`` of the branch's *to* bus (the side of MATPOWER's series impedance; both ends share
  it on a line), stated in ``kv_base``. ``length_km`` is 0: MATPOWER has no lengths.
  Off-nominal taps are accepted (a DC flow on a radial feeder does not depend on them); phase
  shifters are refused. Parallel branches are merged (parallel impedance, summed ratings).
- ``limit_kw``: ``RATE_A`` (MVA) x 1000, i.e. 1 MVA -> 1000 kW: the DC model's flows are active
  power at unity power factor; ``RATE_A`` 0 means unlimited (``inf``); ``ratings=False`` ignores
  the ratings (every limit ``inf``).
- loads: one per bus with ``PD`` other than 0, named ``load<bus>``, columns ``bus``, ``p_kw``
  (``PD`` x 1000), ``q_kvar`` (``QD`` x 1000; carried along, unused by the active-power
  dispatch) and ``kind``: ``load``, or ``injection`` for a negative ``PD`` (distributed
  generation stated as negative demand, as in ``case533mt_hi``/``_lo``): a fixed injection
  that the dispatch does not move.
- fleet: the in-service generators (``GEN_STATUS`` > 0) with polynomial ``gencost`` rows
  (model 2, at most quadratic), named ``G<bus>`` (``G<bus>_2``, ... for more on one bus),
  ``pmin_kw``/``pmax_kw`` = ``PMIN``/``PMAX`` (MW) x 1000: MATPOWER's cost is ``c2 P^2 + c1 P +
  c0`` per hour with ``P`` in MW, the fleet's ``a + b P + c P^2`` in the same units, so ``c =
  c2``, ``b = c1``, ``a = c0`` (the currency is taken as EUR; start-up/shut-down costs are
  ignored). A generator without usable cost data is left out, named in a
  :class:`UserWarning`. ``fleet`` (a fleet table or the path of a fleet file, see
  :mod:`popdispatch.feeder.generators`) replaces the case's generators.
"""

from __future__ import annotations

import io
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components, depth_first_order

from popdispatch.errors import FeederError, OptionError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.generators import as_fleet, make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.radial import join_feeders, merge_parallel

KW_PER_MW = 1000.0
KW_PER_MVA = 1000.0  # DC flows are active power at unity power factor: 1 MVA of RATE_A = 1000 kW

#: Outputs of MATPOWER's idx_* functions in order, with their (1-based) values.
IDX_FUNCTIONS: dict[str, list[tuple[str, int]]] = {
    "idx_bus": [
        ("PQ", 1), ("PV", 2), ("REF", 3), ("NONE", 4), ("BUS_I", 1), ("BUS_TYPE", 2), ("PD", 3),
        ("QD", 4), ("GS", 5), ("BS", 6), ("BUS_AREA", 7), ("VM", 8), ("VA", 9), ("BASE_KV", 10),
        ("ZONE", 11), ("VMAX", 12), ("VMIN", 13), ("LAM_P", 14), ("LAM_Q", 15), ("MU_VMAX", 16),
        ("MU_VMIN", 17),
    ],
    "idx_brch": [
        ("F_BUS", 1), ("T_BUS", 2), ("BR_R", 3), ("BR_X", 4), ("BR_B", 5), ("RATE_A", 6),
        ("RATE_B", 7), ("RATE_C", 8), ("TAP", 9), ("SHIFT", 10), ("BR_STATUS", 11), ("PF", 14),
        ("QF", 15), ("PT", 16), ("QT", 17), ("MU_SF", 18), ("MU_ST", 19), ("ANGMIN", 12),
        ("ANGMAX", 13), ("MU_ANGMIN", 20), ("MU_ANGMAX", 21),
    ],
    "idx_gen": [
        ("GEN_BUS", 1), ("PG", 2), ("QG", 3), ("QMAX", 4), ("QMIN", 5), ("VG", 6), ("MBASE", 7),
        ("GEN_STATUS", 8), ("PMAX", 9), ("PMIN", 10), ("MU_PMAX", 22), ("MU_PMIN", 23),
        ("MU_QMAX", 24), ("MU_QMIN", 25), ("PC1", 11), ("PC2", 12), ("QC1MIN", 13),
        ("QC1MAX", 14), ("QC2MIN", 15), ("QC2MAX", 16), ("RAMP_AGC", 17), ("RAMP_10", 18),
        ("RAMP_30", 19), ("RAMP_Q", 20), ("APF", 21),
    ],
    "idx_cost": [
        ("PW_LINEAR", 1), ("POLYNOMIAL", 2), ("MODEL", 1), ("STARTUP", 2), ("SHUTDOWN", 3),
        ("NCOST", 4), ("COST", 5),
    ],
}  # fmt: skip

_COL = {name: value for outputs in IDX_FUNCTIONS.values() for name, value in outputs}
MATRIX_FIELDS = ("bus", "gen", "branch", "gencost", "areas")
CELL_FIELDS = ("bus_name", "gentype", "genfuel")
#: Minimum number of columns MATPOWER requires of each matrix (version 2).
MIN_COLUMNS = {"bus": 13, "gen": 10, "branch": 11}
_FUNCTIONS = {
    "sqrt": np.sqrt, "abs": np.abs, "exp": np.exp, "log": np.log, "log10": np.log10,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos,
    "atan": np.arctan,
}  # fmt: skip
_BUILTINS = {"Inf": np.inf, "inf": np.inf, "pi": np.pi}


class _Refused(Exception):
    """A statement (or part of it) this reader does not understand; message says why."""


# -- splitting the file into statements -------------------------------------------------------

_PLAIN_LINE = re.compile(r"[%'\[\](){}]|\.\.\.")


def _statements(text: str, path: Path) -> list[tuple[int, str]]:
    """``(line number, statement)`` pairs: comments removed, continuations joined, statements
    split at ``;`` and line ends outside brackets; inside brackets a line end is a row ``;``."""
    out: list[tuple[int, str]] = []
    buf: list[str] = []
    start = 0
    depth = 0
    block_comment = False

    def flush() -> None:
        nonlocal start
        statement = "".join(buf).strip()
        buf.clear()
        if statement:
            out.append((start, statement))
        start = 0

    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if block_comment:
            block_comment = stripped != "%}"
            continue
        if stripped == "%{" and not buf:
            block_comment = True
            continue
        if not _PLAIN_LINE.search(raw):  # fast path: data rows and simple statements
            if depth:
                buf.append(raw + ";")
                continue
            pieces = raw.split(";")
            for piece in pieces:
                if piece.strip():
                    start = start or number
                    buf.append(piece)
                flush()
            continue
        continued = False
        prev = ""  # previous non-blank character of code on this line
        i = 0
        while i < len(raw):
            ch = raw[i]
            if ch == "%":
                break
            if raw.startswith("...", i):
                continued = True
                break
            if ch == "'" and (prev == "" or prev in "=([{,;"):  # a string (else a transpose)
                end = i + 1
                while True:
                    end = raw.find("'", end)
                    if end < 0:
                        raise FeederError(f"{path}:{number}: unterminated string: {raw.strip()!r}")
                    if raw.startswith("''", end):
                        end += 2
                        continue
                    break
                start = start or number
                buf.append(raw[i : end + 1])
                prev = "'"
                i = end + 1
                continue
            if ch in "([{":
                depth += 1
            elif ch in ")]}":
                depth -= 1
                if depth < 0:
                    raise FeederError(f"{path}:{number}: unbalanced {ch!r}: {raw.strip()!r}")
            if ch == ";" and depth == 0:
                flush()
                prev = ""
                i += 1
                continue
            if not ch.isspace():
                start = start or number
                prev = ch
            buf.append(ch)
            i += 1
        if continued:
            buf.append(" ")
        elif depth:
            buf.append(";")
        else:
            flush()
    if depth:
        statement = _short("".join(buf))
        raise FeederError(f"{path}:{start}: unclosed bracket at end of file: {statement!r}")
    flush()
    return out


def _short(statement: str, limit: int = 80) -> str:
    text = " ".join(statement.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


# -- the expression evaluator -----------------------------------------------------------------

_TOKEN = re.compile(
    r"""(?P<space>\s+)
    |(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
    |(?P<name>[A-Za-z_]\w*)
    |(?P<string>'(?:[^']|'')*')
    |(?P<op>\.\*|\./|\.\^|[-+*/^()\[\],;:=.{}])""",
    re.X,
)


@dataclass(frozen=True)
class _Token:
    kind: str  # number, name, string, op, end
    text: str
    space: bool  # blank before the token


def _tokenize(statement: str) -> list[_Token]:
    tokens: list[_Token] = []
    position, space = 0, False
    while position < len(statement):
        match = _TOKEN.match(statement, position)
        if match is None:
            raise _Refused(f"unexpected character {statement[position]!r}")
        position = match.end()
        if match.lastgroup == "space":
            space = True
            continue
        tokens.append(_Token(match.lastgroup, match.group(), space))
        space = False
    tokens.append(_Token("end", "", space))
    return tokens


def _scalar(value: float) -> np.ndarray:
    return np.full((1, 1), float(value))


def _binary(op: str, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    scalar = left.size == 1 or right.size == 1
    if op in ("*", "/", "^") and not (
        (op == "*" and scalar) or (op == "/" and right.size == 1) or (left.size == right.size == 1)
    ):
        raise _Refused(f"matrix {op!r} of {left.shape} and {right.shape} blocks is not supported")
    if not scalar and left.shape != right.shape:
        raise _Refused(f"{op!r} of blocks of different shapes {left.shape} and {right.shape}")
    with np.errstate(all="ignore"):
        if op in ("+",):
            return left + right
        if op == "-":
            return left - right
        if op in ("*", ".*"):
            return left * right
        if op in ("/", "./"):
            return left / right
        return np.power(left, right)


class _Case:
    """The state of a MATPOWER file being interpreted: matrices, baseMVA, named scalars."""

    def __init__(self) -> None:
        self.matrices: dict[str, np.ndarray] = {}
        self.base_mva: float | None = None
        self.names: dict[str, float] = {}

    def matrix(self, name: str) -> np.ndarray:
        if name not in self.matrices:
            raise _Refused(f"mpc.{name} is used before it is defined")
        return self.matrices[name]


class _Parser:
    """Recursive-descent evaluator of one statement (MATLAB precedence, scalars and blocks)."""

    def __init__(self, statement: str, case: _Case) -> None:
        self.tokens = _tokenize(statement)
        self.pos = 0
        self.case = case
        self.matrix_mode = [False]

    # token helpers
    def peek(self, ahead: int = 0) -> _Token:
        return self.tokens[min(self.pos + ahead, len(self.tokens) - 1)]

    def take(self) -> _Token:
        token = self.peek()
        self.pos += 1
        return token

    def expect(self, text: str) -> None:
        token = self.take()
        if token.text != text or token.kind == "string":
            raise _Refused(f"expected {text!r}, found {token.text or 'end of statement'!r}")

    def at(self, *texts: str) -> bool:
        token = self.peek()
        return token.kind == "op" and token.text in texts

    # statements
    def statement(self) -> None:
        first = self.peek()
        if first.kind != "name":
            raise _Refused("not an assignment this reader understands")
        if first.text != "mpc":
            self.take()
            self.expect("=")
            value = self.expression()
            self.end()
            if value.size != 1:
                raise _Refused(f"{first.text} is not a scalar (shape {value.shape})")
            self.case.names[first.text] = float(value[0, 0])
            return
        self.take()
        self.expect(".")
        name = self.take()
        if name.kind != "name":
            raise _Refused("expected a field name after 'mpc.'")
        if self.at("("):
            rows, cols = self.indices(name.text)
            self.expect("=")
            value = self.expression()
            self.end()
            target = self.case.matrix(name.text)
            shape = (len(rows), len(cols))
            if value.size != 1 and value.shape != shape:
                raise _Refused(f"cannot assign a {value.shape} block to a {shape} block")
            target[np.ix_(rows, cols)] = value
            return
        self.expect("=")
        value = self.expression()
        self.end()
        if name.text == "baseMVA":
            if value.size != 1:
                raise _Refused("mpc.baseMVA is not a scalar")
            self.case.base_mva = float(value[0, 0])
        elif name.text in MATRIX_FIELDS:
            self.case.matrices[name.text] = value.copy()
        else:
            raise _Refused(f"unsupported MATPOWER field mpc.{name.text}")

    def end(self) -> None:
        if self.peek().kind != "end":
            raise _Refused(f"unexpected {self.peek().text!r}")

    # expressions, lowest precedence first
    def expression(self) -> np.ndarray:
        value = self.term()
        while self.at("+", "-"):
            token, after = self.peek(), self.peek(1)
            if self.matrix_mode[-1] and token.space and not after.space:
                break  # `[1 -2]`: a new element
            self.take()
            value = _binary(token.text, value, self.term())
        return value

    def term(self) -> np.ndarray:
        value = self.unary()
        while self.at("*", "/", ".*", "./"):
            op = self.take().text
            value = _binary(op, value, self.unary())
        return value

    def unary(self) -> np.ndarray:
        if self.at("-", "+"):
            sign = -1.0 if self.take().text == "-" else 1.0
            return sign * self.unary()
        return self.power()

    def power(self) -> np.ndarray:
        value = self.primary()
        while self.at("^", ".^"):
            op = self.take().text
            sign = 1.0
            while self.at("-", "+"):
                sign *= -1.0 if self.take().text == "-" else 1.0
            value = _binary(op, value, sign * self.primary())
        return value

    def primary(self) -> np.ndarray:
        token = self.take()
        if token.kind == "number":
            return _scalar(float(token.text))
        if token.kind == "op" and token.text == "(":
            self.matrix_mode.append(False)
            value = self.expression()
            self.expect(")")
            self.matrix_mode.pop()
            return value
        if token.kind == "op" and token.text == "[":
            return self.bracket()
        if token.kind == "name":
            if token.text == "mpc":
                self.expect(".")
                name = self.take()
                if name.kind != "name":
                    raise _Refused("expected a field name after 'mpc.'")
                if name.text == "baseMVA":
                    if self.case.base_mva is None:
                        raise _Refused("mpc.baseMVA is used before it is defined")
                    return _scalar(self.case.base_mva)
                if name.text not in MATRIX_FIELDS:
                    raise _Refused(f"unsupported MATPOWER field mpc.{name.text}")
                if self.at("("):
                    rows, cols = self.indices(name.text)
                    return self.case.matrix(name.text)[np.ix_(rows, cols)].copy()
                return self.case.matrix(name.text).copy()
            if token.text in _FUNCTIONS and self.at("("):
                self.take()
                self.matrix_mode.append(False)
                argument = self.expression()
                self.expect(")")
                self.matrix_mode.pop()
                with np.errstate(all="ignore"):
                    return _FUNCTIONS[token.text](argument)
            if token.text in self.case.names:
                return _scalar(self.case.names[token.text])
            if token.text in _BUILTINS:
                return _scalar(_BUILTINS[token.text])
            raise _Refused(f"unknown name {token.text!r}")
        raise _Refused(f"unexpected {token.text or 'end of statement'!r}")

    def bracket(self) -> np.ndarray:
        """A ``[...]`` matrix literal (the ``[`` is taken): rows by ``;``, elements by blanks
        or commas."""
        self.matrix_mode.append(True)
        rows: list[list[np.ndarray]] = [[]]
        while not self.at("]"):
            if self.peek().kind == "end":
                raise _Refused("unclosed '['")
            if self.at(";"):
                self.take()
                rows.append([])
            elif self.at(","):
                self.take()
            else:
                rows[-1].append(self.expression())
        self.take()
        self.matrix_mode.pop()
        blocks = [np.hstack(row) for row in rows if row]
        if not blocks:
            return np.zeros((0, 0))
        try:
            return np.vstack(blocks)
        except ValueError:
            raise _Refused("rows of different lengths") from None

    def indices(self, field_name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(ROWS, COLS)`` of ``mpc.X(ROWS, COLS)`` as 0-based index arrays."""
        matrix = self.case.matrix(field_name)
        self.expect("(")
        self.matrix_mode.append(False)
        result = []
        for axis in (0, 1):
            if axis:
                self.expect(",")
            if self.at(":") and self.peek(1).text in (",", ")"):
                self.take()
                result.append(np.arange(matrix.shape[axis]))
                continue
            values = self.expression().ravel()
            size = matrix.shape[axis]
            bad = (values != np.round(values)) | (values < 1) | (values > size)
            if bad.any():
                what = "row" if axis == 0 else "column"
                raise _Refused(
                    f"{what} index {values[bad][0]:g} is not an integer in 1..{size} of "
                    f"mpc.{field_name}"
                )
            result.append(values.astype(np.int64) - 1)
        self.expect(")")
        self.matrix_mode.pop()
        return result[0], result[1]


# -- interpreting a file ---------------------------------------------------------------------

_FUNCTION = re.compile(r"function\s+(?:\[?\s*\w+\s*\]?\s*=\s*)?\w+\s*(?:\(\s*\))?")
_VERSION = re.compile(r"mpc\.version\s*=\s*'([^']*)'")
_CELL = re.compile(r"mpc\.(\w+)\s*=\s*\{.*\}", re.S)
_IDX = re.compile(r"\[([\w\s,]*)\]\s*=\s*(\w+)")
_MATRIX = re.compile(r"mpc\.(\w+)\s*=\s*\[([^\[\]()]*)\]", re.S)
_NUMERIC = re.compile(r"[\s\d.eE+\-,;Infai]*")


def _fast_matrix(body: str) -> np.ndarray | None:
    """A matrix of plain numbers without the evaluator (pandas' C parser), or None to let the
    evaluator decide (expressions such as ``1 - 2``, rows of different lengths)."""
    if not _NUMERIC.fullmatch(body):
        return None
    text = body.replace(",", " ").replace("\n", ";")
    if not text.replace(";", "").strip():
        return np.zeros((0, 0))
    try:
        table = pd.read_csv(
            io.StringIO(text), sep=r"\s+", header=None, lineterminator=";", dtype=float,
            engine="c",
        )  # fmt: skip
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    values = table.to_numpy(float)
    return None if np.isnan(values).any() else values


def _interpret(statement: str, case: _Case) -> None:
    if _FUNCTION.fullmatch(statement):
        return
    if statement == "define_constants":
        case.names.update(_COL)
        for outputs in IDX_FUNCTIONS.values():
            case.names.update(dict(outputs))
        return
    version = _VERSION.fullmatch(statement)
    if version:
        if version.group(1) != "2":
            raise _Refused(f"MATPOWER case format version {version.group(1)!r} (only '2')")
        return
    cell = _CELL.fullmatch(statement)
    if cell:
        if cell.group(1) not in CELL_FIELDS:
            raise _Refused(f"unsupported MATPOWER field mpc.{cell.group(1)}")
        return
    idx = _IDX.fullmatch(statement)
    if idx:
        names = idx.group(1).replace(",", " ").split()
        outputs = IDX_FUNCTIONS.get(idx.group(2))
        if outputs is None:
            raise _Refused(f"unknown function {idx.group(2)!r}")
        if len(names) > len(outputs):
            raise _Refused(f"{idx.group(2)} has only {len(outputs)} outputs")
        for name, (_, value) in zip(names, outputs, strict=False):
            case.names[name] = float(value)
        return
    matrix = _MATRIX.fullmatch(statement)
    if matrix and matrix.group(1) in MATRIX_FIELDS:
        values = _fast_matrix(matrix.group(2))
        if values is not None:
            case.matrices[matrix.group(1)] = values
            return
    _Parser(statement, case).statement()


def parse_matpower(path: str | Path) -> tuple[float, dict[str, np.ndarray]]:
    """Interpret a MATPOWER case file: ``(baseMVA, {"bus": ..., "gen": ..., ...})``.

    The matrices are as MATLAB would hold them after running the file (every statement applied,
    in order; MATPOWER's units: MW, MVAr, p.u., kV). Raises :class:`FeederError` naming the
    file, line and statement on anything not understood (see the module docstring).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise FeederError(f"cannot read MATPOWER case {path}: {exc}") from None
    case = _Case()
    for number, statement in _statements(text, path):
        try:
            _interpret(statement, case)
        except _Refused as exc:
            raise FeederError(
                f"{path}:{number}: {exc}; unsupported statement: {_short(statement)!r}"
            ) from None
    if case.base_mva is None or not case.base_mva > 0:
        raise FeederError(f"{path}: mpc.baseMVA is missing or not positive")
    for name in ("bus", "branch"):
        if name not in case.matrices:
            raise FeederError(f"{path}: mpc.{name} is missing")
    for name, columns in MIN_COLUMNS.items():
        matrix = case.matrices.get(name)
        if matrix is not None and not matrix.size:
            case.matrices[name] = np.zeros((0, columns))
        elif matrix is not None and matrix.shape[1] < columns:
            raise FeederError(
                f"{path}: mpc.{name} has {matrix.shape[1]} columns, MATPOWER needs {columns}"
            )
    return case.base_mva, case.matrices


# -- building the feeder ---------------------------------------------------------------------


def _col(matrix: np.ndarray, name: str) -> np.ndarray:
    return matrix[:, _COL[name] - 1]


def _bus_ids(values: np.ndarray, what: str, path: Path) -> np.ndarray:
    bad = values != np.round(values)
    if bad.any():
        raise FeederError(f"{path}: {what} {values[bad][0]:g} is not an integer bus number")
    return values.astype(np.int64)


def read_matpower(
    path: str | Path,
    *,
    fleet: pd.DataFrame | None = None,
    root: int | None = None,
    ratings: bool = True,
) -> Feeder:
    """Read a MATPOWER case file into a radial :class:`~popdispatch.feeder.Feeder`.

    See the module docstring for the statements understood and the unit conversions.

    Parameters
    ----------
    path : the ``.m`` case file; the feeder is named after its stem (e.g. ``case33bw``).
    fleet : a fleet table (see :mod:`popdispatch.feeder.generators`; ``bus`` = MATPOWER bus
        number) replacing the case's own generators and costs.
    root : the source bus (MATPOWER bus number); default the reference bus (``BUS_TYPE`` 3).
    ratings : take line limits from ``RATE_A`` (1 MVA -> 1000 kW, 0 = unlimited); ``False``
        leaves every line unlimited.
    """
    path = Path(path)
    fleet = as_fleet(fleet)
    base_mva, mpc = parse_matpower(path)
    bus, branch = mpc["bus"], mpc["branch"]
    ids = _bus_ids(_col(bus, "BUS_I"), "bus", path)
    if len(np.unique(ids)) != len(ids):
        twice = pd.Index(ids)[pd.Index(ids).duplicated()][0]
        raise FeederError(f"{path}: bus {twice} is defined twice in mpc.bus")
    isolated = _col(bus, "BUS_TYPE") == 4
    shunt = (_col(bus, "GS") != 0) & ~isolated
    if shunt.any():
        k = int(np.flatnonzero(shunt)[0])
        raise FeederError(
            f"{path}: bus {ids[k]} has shunt conductance GS = {_col(bus, 'GS')[k]:g} MW: not "
            "supported"
        )

    on = _col(branch, "BR_STATUS") != 0
    rows = np.flatnonzero(on)
    from_bus = _bus_ids(_col(branch, "F_BUS")[on], "branch end", path)
    to_bus = _bus_ids(_col(branch, "T_BUS")[on], "branch end", path)
    kept = pd.Index(ids[~isolated])
    for end in (from_bus, to_bus):
        unknown = ~np.isin(end, kept)
        if unknown.any():
            k = int(np.flatnonzero(unknown)[0])
            raise FeederError(
                f"{path}: in-service branch {rows[k] + 1} ({from_bus[k]}-{to_bus[k]}) ends at "
                f"{'an isolated' if np.isin(end[k], ids) else 'an unknown'} bus {end[k]}"
            )
    shift = _col(branch, "SHIFT")[on]
    if (shift != 0).any():
        k = int(np.flatnonzero(shift != 0)[0])
        raise FeederError(
            f"{path}: branch {rows[k] + 1} ({from_bus[k]}-{to_bus[k]}) is a phase-shifting "
            f"transformer (SHIFT = {shift[k]:g}): not supported"
        )

    refs = ids[(_col(bus, "BUS_TYPE") == 3) & ~isolated].tolist()
    if root is None:
        if not refs:
            raise FeederError(f"{path}: no reference bus (BUS_TYPE 3): name the source bus "
                              "(--root BUS)")  # fmt: skip
        sources = [int(r) for r in refs]
    else:
        sources = [_root_bus(root, path)]
        if sources[0] not in kept:
            raise OptionError(f"{path}: root {root} is not a bus of the case", "--root")
    source = sources[0]

    # keep the source's part of the network (and any other part with load unless root is given)
    n = len(kept)
    ends_a, ends_b = kept.get_indexer(from_bus), kept.get_indexer(to_bus)
    graph = csr_array((np.ones(len(rows)), (ends_a, ends_b)), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    pd_mw = pd.Series(_col(bus, "PD"), index=ids).loc[kept].to_numpy()
    loaded = np.bincount(component, weights=(pd_mw != 0).astype(float))
    trees = [int(component[kept.get_loc(s)]) for s in sources]
    if len(set(trees)) < len(trees):
        raise FeederError(
            f"{path}: reference buses {sources} feed one connected network: popdispatch "
            "supports one source per radial feeder; pick one (--root BUS)"
        )
    keep = np.isin(component, trees)
    if root is None:
        keep |= loaded[component] > 0
    keep_bus = kept[keep]
    line_on = keep[ends_a]
    rows, from_bus, to_bus = rows[line_on], from_bus[line_on], to_bus[line_on]

    bus_table = pd.DataFrame(bus, index=ids)
    kv = bus_table.loc[to_bus, _COL["BASE_KV"] - 1].to_numpy()
    if (kv <= 0).any():
        k = int(np.flatnonzero(kv <= 0)[0])
        raise FeederError(
            f"{path}: bus {to_bus[k]} has baseKV = {kv[k]:g}: impedances of branch {rows[k] + 1} "
            "cannot be converted to ohm"
        )
    z_base = kv**2 / base_mva
    rate = _col(branch, "RATE_A")[rows]
    limit = np.where(rate == 0, np.inf, rate * KW_PER_MVA)
    if not ratings:
        limit = np.full(len(rows), np.inf)
    names = pd.Series([f"L{a}-{b}" for a, b in zip(from_bus, to_bus, strict=True)])
    repeated = names.duplicated(keep="first").to_numpy()
    names[repeated] = [f"{names[k]}#{rows[k] + 1}" for k in np.flatnonzero(repeated)]
    lines = pd.DataFrame(
        {
            "from_bus": from_bus,
            "to_bus": to_bus,
            "length_km": 0.0,
            "r_ohm": _col(branch, "BR_R")[rows] * z_base,
            "x_ohm": _col(branch, "BR_X")[rows] * z_base,
            "limit_kw": limit,
            "kv_base": kv,
        },
        index=pd.Index(names.tolist(), name="line"),
    )
    lines, _ = merge_parallel(lines)

    loads_at = bus_table.loc[keep_bus]
    loads_at = loads_at[loads_at[_COL["PD"] - 1] != 0]
    p_kw = loads_at[_COL["PD"] - 1].to_numpy(float) * KW_PER_MW
    loads = pd.DataFrame(
        {
            "bus": loads_at.index.to_numpy(np.int64),
            "p_kw": p_kw,
            "q_kvar": loads_at[_COL["QD"] - 1].to_numpy(float) * KW_PER_MW,
            "kind": np.where(p_kw < 0, "injection", "load"),
        },
        index=pd.Index([f"load{b}" for b in loads_at.index], name="load"),
    )
    trees_buses = [keep_bus[component[keep] == t] for t in trees]
    buses = pd.concat(
        [_layout(part, from_bus, to_bus, s) for part, s in zip(trees_buses, sources, strict=True)]
        + [_layout(keep_bus.difference(np.concatenate(trees_buses)), from_bus, to_bus, None)]
    ).loc[keep_bus]
    buses["vn_kv"] = bus_table.loc[buses.index, _COL["BASE_KV"] - 1].to_numpy(float)
    if len(sources) > 1:
        buses["y"] = buses["y"] + _offsets(buses, trees_buses)
        buses, lines, source = join_feeders(buses, lines, sources)
    generators = _fleet(path, mpc, set(keep_bus.tolist())) if fleet is None else fleet
    return Feeder(path.stem, buses, lines, loads, source, generators)


def _root_bus(root, path: Path) -> int:
    """The MATPOWER bus number ``root`` spells; :class:`FeederError` otherwise."""
    try:
        return int(str(root).strip())
    except ValueError:
        raise OptionError(
            f"{path}: root {root!r} is not a MATPOWER bus number", "--root"
        ) from None


def _offsets(buses: pd.DataFrame, trees: list[pd.Index]) -> np.ndarray:
    """Schematic ``y`` offsets that stack separate feeders one above the other."""
    offset = pd.Series(0.0, index=buses.index)
    shift = 0.0
    for part in trees:
        offset[part] = shift
        shift += float(buses.loc[part, "y"].max()) + 2.0
    return offset.to_numpy()


def _layout(
    buses: pd.Index, from_bus: np.ndarray, to_bus: np.ndarray, source: int | None
) -> pd.DataFrame:
    """Schematic coordinates of ``buses``: ``x`` = hops from the source, ``y`` = leaves before
    the bus in depth-first order (unreachable buses, and all without a source, at 0, 0; the
    feeder then reports them)."""
    n = len(buses)
    x = np.zeros(n)
    y = np.zeros(n)
    index = pd.Index(buses.to_numpy(np.int64), name="bus")
    if source is None or n == 0:
        return pd.DataFrame({"x": x, "y": y}, index=index)
    a, b = buses.get_indexer(from_bus), buses.get_indexer(to_bus)
    inside = (a >= 0) & (b >= 0)
    graph = csr_array((np.ones(int(inside.sum())), (a[inside], b[inside])), shape=(n, n))
    order, parent = depth_first_order(graph, buses.get_loc(source), directed=False)
    children = np.bincount(parent[parent >= 0], minlength=n)
    leaves = 0
    for node in order[1:]:
        x[node] = x[parent[node]] + 1
    for node in order:
        y[node] = leaves
        leaves += children[node] == 0
    return pd.DataFrame({"x": x, "y": y}, index=index)


def _fleet(path: Path, mpc: dict[str, np.ndarray], buses: set[int]) -> pd.DataFrame:
    """The case's in-service generators with usable polynomial costs, as a fleet table; the
    others are left out with a :class:`UserWarning` naming them (a case without any priced
    generator has an empty fleet: it can be described, a dispatch needs a fleet)."""
    gen = mpc.get("gen")
    if gen is None or not gen.size:
        return make_fleet([])
    cost = mpc.get("gencost")
    on = np.flatnonzero(_col(gen, "GEN_STATUS") > 0)
    rows, names, unpriced = [], [], []
    for k in on:
        at = _bus_ids(gen[k : k + 1, 0], "generator bus", path)[0]
        if at not in buses:
            continue  # in a part of the network that is not this feeder
        coefficients, why = _polynomial(cost, k)
        if why:
            unpriced.append(f"generator {k + 1} at bus {at} {why}")
            continue
        c0, c1, c2 = coefficients
        rows.append((at, c0, c1, c2, gen[k, _COL["PMIN"] - 1] * KW_PER_MW,
                     gen[k, _COL["PMAX"] - 1] * KW_PER_MW))  # fmt: skip
        count = sum(name == f"G{at}" or name.startswith(f"G{at}_") for name in names)
        names.append(f"G{at}" if count == 0 else f"G{at}_{count + 1}")
    if unpriced:
        warnings.warn(
            f"{path}: left out of the fleet: {'; '.join(unpriced)} (a dispatch of these needs a "
            "fleet: --fleet FILE)",
            UserWarning,
            stacklevel=3,
        )
    return make_fleet(rows, names)


def _polynomial(cost: np.ndarray | None, k: int) -> tuple[tuple[float, float, float], str]:
    """``((c0, c1, c2), "")`` of gencost row ``k``, or ``(None, why)`` when it has none usable."""
    if cost is None or cost.shape[0] <= k:
        return None, "has no cost data (mpc.gencost)"
    model, ncost = cost[k, 0], cost[k, 3]
    if model != 2:
        return None, f"has a non-polynomial cost (model {model:g})"
    coefficients = cost[k, 4 : 4 + int(ncost)]
    if ncost != int(ncost) or len(coefficients) != ncost:
        return None, f"has a bad NCOST = {ncost:g} in gencost row {k + 1}"
    coefficients = np.trim_zeros(coefficients, "f")
    if len(coefficients) > 3:
        return None, f"has a cost polynomial of degree {len(coefficients) - 1} (at most 2)"
    c0, c1, c2 = np.concatenate([coefficients[::-1], np.zeros(3)])[:3]
    return (float(c0), float(c1), float(c2)), ""


# -- any network, meshed or radial: the DC model's tables ------------------------------------


def read_matpower_network(
    path: str | Path, *, fleet: pd.DataFrame | None = None, ratings: bool = True
) -> DcNetwork:
    """Read a MATPOWER case of any shape (meshed or radial) into a
    :class:`~popdispatch.feeder.dcnet.DcNetwork` for MATPOWER's DC model.

    Per-unit impedances as the case has them (no ``baseKV`` needed); in-service branches only
    (parallel ones as separate rows, named ``L<from>-<to>`` and ``#<row>`` on a repeated
    pair), each with ``BR_X``, ``TAP``, ``SHIFT`` and ``RATE_A`` (MVA -> kW at 1000 kW per MVA,
    0 = unlimited; ``ratings=False``: all unlimited); isolated buses (``BUS_TYPE`` 4) dropped;
    ``PD`` and ``GS`` (MW at 1 p.u.) per bus as demand; the slack is the first reference bus
    (``BUS_TYPE`` 3). The fleet is the case's in-service generators with their polynomial
    costs (:func:`read_matpower`'s rules, several per bus named ``G<bus>_2``, ...), or
    ``fleet``. A piecewise-linear cost (gencost model 1) is refused, naming its row.
    """
    path = Path(path)
    base_mva, mpc = parse_matpower(path)
    bus, branch = mpc["bus"], mpc["branch"]
    ids = _bus_ids(_col(bus, "BUS_I"), "bus", path)
    live = _col(bus, "BUS_TYPE") != 4
    buses = pd.DataFrame(
        {"pd_mw": _col(bus, "PD")[live], "gs_mw": _col(bus, "GS")[live]},
        index=pd.Index(ids[live], name="bus"),
    )
    on = np.flatnonzero(_col(branch, "BR_STATUS") != 0)
    ends = [_bus_ids(_col(branch, e)[on], "branch end", path) for e in ("F_BUS", "T_BUS")]
    for end in ends:
        bad = ~np.isin(end, buses.index)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FeederError(f"{path}: in-service branch {on[k] + 1} ({ends[0][k]}-{ends[1][k]}) "
                              f"ends at an isolated or unknown bus {end[k]}")  # fmt: skip
    rate = _col(branch, "RATE_A")[on] * KW_PER_MVA
    names = [f"L{a}-{b}" for a, b in zip(*ends, strict=True)]
    seen: set[str] = set()
    for k, name in enumerate(names):
        names[k] = f"{name}#{on[k] + 1}" if name in seen else name
        seen.add(name)
    lines = pd.DataFrame(
        {"from_bus": ends[0], "to_bus": ends[1], "x_pu": _col(branch, "BR_X")[on],
         "tap": _col(branch, "TAP")[on], "shift_deg": _col(branch, "SHIFT")[on],
         "limit_kw": np.where((rate > 0) & ratings, rate, np.inf)},
        index=pd.Index(names, name="line"),
    )  # fmt: skip
    refs = ids[(_col(bus, "BUS_TYPE") == 3) & live]
    if not len(refs):
        raise FeederError(f"{path}: no reference bus (BUS_TYPE 3)")
    if fleet is None:
        _refuse_piecewise_linear(path, mpc)
        generators = _fleet(path, mpc, set(buses.index.tolist()))
    else:
        generators = as_fleet(fleet)
    return DcNetwork(path.stem, float(base_mva), buses, lines, generators, int(refs[0]))


def _refuse_piecewise_linear(path: Path, mpc: dict[str, np.ndarray]) -> None:
    """One-line :class:`FeederError` naming the first in-service generator whose cost is
    piecewise linear (gencost model 1)."""
    gen, cost = mpc.get("gen"), mpc.get("gencost")
    if gen is None or cost is None:
        return
    rows = min(len(gen), len(cost))
    pwl = np.flatnonzero((cost[:rows, 0] == 1) & (_col(gen[:rows], "GEN_STATUS") > 0))
    if len(pwl):
        k = int(pwl[0])
        raise FeederError(f"{path}: generator {k + 1} (bus {int(gen[k, 0])}) has a piecewise-"
                          "linear cost (gencost model 1): popdispatch takes polynomial costs "
                          "(model 2) of degree at most 2")  # fmt: skip
