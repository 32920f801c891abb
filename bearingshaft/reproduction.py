"""The reproduction report: a run's results folders against the committed reference, stage by stage.

``bearingshaft run`` writes into ``runs/<scene>/``; the committed ``results/<scene>/`` folders are
the reference (``bearingshaft run --update-reference`` rewrites them). At the end of a run every
file each stage wrote is compared with the reference's, as the stage declares in its registry
entry (``Stage.reproduction``, a :class:`Reproduction`, ``REPRODUCTION`` at the end of the stage's module):

- **exact** (the default): deterministic quantities (frequencies, errors, identified parameters,
  mode shapes), compared to the digits they are written with: text equality, cell by cell (CSV) or
  line by line (Markdown, TOML), one unit in the last digit being a value at a rounding boundary
  (:func:`one_unit_apart`). Each stage writes a number only to the digits another CPU's BLAS
  reproduces, and a round-off-level one as the power of ten that bounds it
  (:func:`bearingshaft.digits.roundoff_bound`); a difference is a failure.
- **within** a stated tolerance (:func:`within`; a failure beyond it): numbers written with more
  digits than another machine reproduces, magnitudes (DOP853's error stepping over contact
  switches), round-off bounds (:func:`roundoff`: one decade).
- **chaotic**: quantities of chaotic motion (impact counts, peak tip forces, when the gaps stay
  open), never failures: a difference is reported as "chaotic, not comparable past t = ... s", the
  predictability horizon t_h = ln(:data:`HORIZON_TOL` / :data:`DELTA0`) / lambda, where lambda is
  the largest Lyapunov exponent the run itself measured (the ``exponent_per_s`` column of the file
  the stage names, the largest over its chaotic seeds).
- **sensitive**: set by round-off through a discrete choice (the points an HB continuation lands on,
  a symmetry broken by round-off alone): reported with the reason, never a failure.
- **figures** (and ParaView files): existence only; **run records** (``provenance.json``, files
  named ``*timing*``, arrays that are not committed): not compared.

A rule covers a file, some of its CSV columns (and rows) or Markdown lines; the rest of a file falls
to its whole-file rule, else to :data:`DEFAULT_RULES`.

The report (:func:`write_report`) is ``reproduction.md`` and ``reproduction.csv`` in the run's
parent folder; :func:`summary` is what the command prints. :func:`failed` decides the exit status.
"""

from __future__ import annotations

import csv
import difflib
import fnmatch
import json
import math
import re
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path

EXACT, WITHIN_KIND, CHAOTIC, SENSITIVE, FIGURE, RECORD = "exact", "within", "chaotic", "sensitive", "figure", "record"
KINDS = (EXACT, WITHIN_KIND, CHAOTIC, SENSITIVE, FIGURE, RECORD)
JUDGED = (EXACT, WITHIN_KIND)  # kinds whose differences are failures

DELTA0 = 2.2e-16  # relative separation two machines' runs start with: one rounding of a sum (machine epsilon),
# which another CPU's SIMD kernels change
HORIZON_TOL = 1e-4  # relative: a chaotic quantity is written to 4 significant digits, so the runs are no longer
# comparable once their states differ by 1e-4 of their size

# statuses of a report row
REPRODUCED = "reproduced"  # equal to the digits written
LAST_DIGIT = "last digit"  # one unit apart in the last digit written: the value lies at a rounding boundary
WITHIN = "within tolerance"  # a quantity inside its stated tolerance
DIFFERS = "DIFFERS"  # a deterministic quantity that did not reproduce: a failure
MISSING = "MISSING"  # in the reference, not written by the run: a failure
CHAOTIC_DIFF = "chaotic"  # differs, as chaotic motion does past its horizon: not a failure
SENSITIVE_DIFF = "sensitive"  # differs, for the reason stated: not a failure
EXISTS = "exists"  # a figure written by the run (and in the reference)
NEW = "new"  # written by the run, not in the reference (not committed yet, or not tracked)
NO_REFERENCE = "no reference"  # the scene has no reference folder
FAILURES = (DIFFERS, MISSING)

MAX_CELLS_LISTED = 5  # differing cells of one column listed in the Markdown report (all are in the CSV)


@dataclass(frozen=True, slots=True)
class Rule:
    """How a stage's files (or some of their columns or lines) are compared with the reference.

    Parameters
    ----------
    pattern : str
        File names it applies to (``fnmatch`` pattern: ``"levels.csv"``, ``"*.png"``).
    kind : str
        ``exact``, ``within``, ``chaotic``, ``sensitive``, ``figure`` or ``record`` (module docstring).
    parts : tuple of str
        CSV columns (``fnmatch`` patterns) or, for text files, regular expressions of the lines it
        covers; empty: the whole file (what no part rule covers).
    why : str
        What the report says of a difference (the quantity and why it is not reproduced exactly).
    rtol, atol, factor : float
        ``within`` only: a number reproduces if |run - ref| <= atol + rtol |ref|, or if run / ref and
        its inverse are at most ``factor`` (> 1); a text cell or line if its numbers do and the rest
        is equal.
    rows : str
        CSV only: a regular expression the reference row (its cells joined by commas) must match for
        the rule to apply to it (empty: every row).
    """

    pattern: str
    kind: str
    parts: tuple[str, ...] = ()
    why: str = ""
    rtol: float = 0.0
    atol: float = 0.0
    factor: float = 0.0
    rows: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")
        tolerances = (self.rtol, self.atol, self.factor)
        if self.kind == WITHIN_KIND and not any(tolerances):
            raise ValueError(f"a within rule ({self.pattern}) needs rtol, atol or factor")
        if self.kind != WITHIN_KIND and any(tolerances):
            raise ValueError(f"only a within rule has tolerances, not {self.kind!r} ({self.pattern})")
        if min(tolerances) < 0 or (self.factor and self.factor <= 1.0):
            raise ValueError(f"tolerances are >= 0 and a factor > 1 ({self.pattern})")
        if not self.why and self.kind in (WITHIN_KIND, CHAOTIC, SENSITIVE):
            raise ValueError(f"a {self.kind} rule says why ({self.pattern})")

    def covers(self, name: str) -> bool:
        return fnmatch.fnmatchcase(name, self.pattern)

    def covers_row(self, row: list[str]) -> bool:
        return not self.rows or re.search(self.rows, ",".join(row)) is not None

    def covers_part(self, part: str, csv_column: bool) -> bool:
        if csv_column:
            return any(fnmatch.fnmatchcase(part, p) for p in self.parts)
        return any(re.search(p, part) for p in self.parts)

    def tolerance(self) -> str:
        """The tolerance as the report states it."""
        terms = [f"{name} {v:g}" for name, v in (("rtol", self.rtol), ("atol", self.atol), ("factor", self.factor))
                 if v]
        return ", ".join(terms)


def exact(pattern: str, *parts: str, why: str = "", rows: str = "") -> Rule:
    """Deterministic: compared to the digits written (text equality; one unit in the last digit is a
    value at a rounding boundary); a difference is a failure.

    Parameters
    ----------
    pattern : str
        File names.
    *parts : str
        CSV columns (fnmatch) or line regexes; none: the whole file.
    why : str
        What it holds.
    rows : str
        CSV rows it applies to (:class:`Rule`).

    Returns
    -------
    Rule
    """
    return Rule(pattern, EXACT, parts, why, rows=rows)


def within(pattern: str, *parts: str, why: str, rtol: float = 0.0, atol: float = 0.0, factor: float = 0.0,
           rows: str = "") -> Rule:
    """Deterministic to a stated tolerance (a failure beyond it): numbers written with more digits than
    another machine reproduces, or magnitudes.

    Parameters
    ----------
    pattern : str
        File names.
    *parts : str
        CSV columns (fnmatch) or line regexes; none: the whole file.
    why : str
        Why the tolerance is what it is.
    rtol, atol, factor : float
        As :class:`Rule`.
    rows : str
        CSV rows it applies to (:class:`Rule`).

    Returns
    -------
    Rule
    """
    return Rule(pattern, WITHIN_KIND, parts, why, rtol, atol, factor, rows)


def roundoff(pattern: str, *parts: str, rows: str = "") -> Rule:
    """A round-off-level quantity written as the power of ten that bounds it
    (:func:`bearingshaft.digits.roundoff_bound`): another machine may move it by one decade.

    Parameters
    ----------
    pattern : str
        File names.
    *parts : str
        CSV columns (fnmatch) or line regexes; none: the whole file.
    rows : str
        CSV rows it applies to (:class:`Rule`).

    Returns
    -------
    Rule
    """
    return within(pattern, *parts, factor=10.0, rows=rows, why="round-off, written as the power of ten that bounds "
                  "it; another CPU may move it by one decade")


def chaotic(pattern: str, *parts: str, why: str, rows: str = "") -> Rule:
    """Quantities of chaotic motion: a difference is reported with the run's predictability horizon.

    Parameters
    ----------
    pattern : str
        File names.
    *parts : str
        CSV columns (fnmatch) or line regexes; none: the whole file.
    why : str
        The quantities, for the report.
    rows : str
        CSV rows it applies to (:class:`Rule`).

    Returns
    -------
    Rule
    """
    return Rule(pattern, CHAOTIC, parts, why, rows=rows)


def sensitive(pattern: str, *parts: str, why: str, rows: str = "") -> Rule:
    """Quantities set by round-off through a discrete choice (a continuation's step path, a symmetry
    broken by round-off): a difference is reported with ``why``, never a failure.

    Parameters
    ----------
    pattern : str
        File names.
    *parts : str
        CSV columns (fnmatch) or line regexes; none: the whole file.
    why : str
        Why they are sensitive.
    rows : str
        CSV rows it applies to (:class:`Rule`).

    Returns
    -------
    Rule
    """
    return Rule(pattern, SENSITIVE, parts, why, rows=rows)


def figure(pattern: str) -> Rule:
    """A figure or a picture file: its existence is checked.

    Parameters
    ----------
    pattern : str
        File names.

    Returns
    -------
    Rule
    """
    return Rule(pattern, FIGURE)


def record(pattern: str, why: str = "a record of the run") -> Rule:
    """A run record (times, provenance): not compared.

    Parameters
    ----------
    pattern : str
        File names.
    why : str
        What it records.

    Returns
    -------
    Rule
    """
    return Rule(pattern, RECORD, (), why)


# every stage's files fall back on these, after its own rules: figures exist, run records are not compared,
# arrays that are not committed (*.npz, the hammer's .uff, see .gitignore) are records too; anything else is exact
DEFAULT_RULES = (
    record("provenance.json", "the run's commit, date and wall times"),
    record("*timing*", "wall-clock times"),
    figure("*.png"),
    figure("*.vtu"),
    record("*.npz", "arrays, not committed (.gitignore)"),
    exact("*"),
)


@dataclass(frozen=True, slots=True)
class Reproduction:
    """How one stage's files are compared with the reference (its registry entry's ``reproduction``).

    Parameters
    ----------
    rules : tuple of Rule
        Searched in order before :data:`DEFAULT_RULES`; a whole-file rule decides the file's
        parts that no part rule covers.
    lyapunov : tuple of str
        Files of the scene's folder (written by this stage or an earlier one) whose
        ``exponent_per_s`` column (or the column named after a colon: ``"response_map.csv:lyapunov_per_s"``)
        holds the largest Lyapunov exponent of the run's motion: the horizon of its chaotic quantities.
    """

    rules: tuple[Rule, ...] = ()
    lyapunov: tuple[str, ...] = ()

    def whole(self, name: str) -> Rule:
        return next(r for r in (*self.rules, *DEFAULT_RULES) if not r.parts and r.covers(name))

    def part_rules(self, name: str) -> tuple[Rule, ...]:
        return tuple(r for r in self.rules if r.parts and r.covers(name))


@dataclass(frozen=True, slots=True)
class Row:
    """One line of the report: a file, or a quantity in it, and how it compared.

    Parameters
    ----------
    scene, stage, file : str
        Where (``stage`` is ``"folder"`` for ``scene.toml``).
    status : str
        :data:`REPRODUCED`, :data:`DIFFERS`, :data:`CHAOTIC_DIFF`, ... (module constants).
    quantity : str
        A CSV cell (``column [key]``) or a line (``line N``); empty for the whole file.
    reference, run : str
        The values as written (shortened).
    note : str
        Why it may differ, the horizon, or what failed.
    """

    scene: str
    stage: str
    file: str
    status: str
    quantity: str = ""
    reference: str = ""
    run: str = ""
    note: str = ""


@dataclass(slots=True)
class Horizon:
    """The predictability horizon of a run, from the largest Lyapunov exponent it measured.

    Parameters
    ----------
    exponent_per_s : float
        1/s, the largest exponent (NaN: not measured).
    source : str
        The file it was read from.
    """

    exponent_per_s: float = math.nan
    source: str = ""

    @property
    def t_s(self) -> float:
        """s, ln(HORIZON_TOL / DELTA0) / lambda (inf for a non-positive exponent, NaN if not measured)."""
        lam = self.exponent_per_s
        if math.isnan(lam):
            return math.nan
        return math.log(HORIZON_TOL / DELTA0) / lam if lam > 0 else math.inf

    def text(self) -> str:
        if math.isnan(self.exponent_per_s):
            return "no Lyapunov exponent measured for this run"
        if math.isinf(self.t_s):
            return f"largest Lyapunov exponent {self.exponent_per_s:.3g} /s ({self.source}): not chaotic"
        return (f"not comparable past t = {self.t_s:.3g} s (largest Lyapunov exponent {self.exponent_per_s:.3g} /s, "
                f"{self.source}; round-off {DELTA0:.1e} grows to {HORIZON_TOL:.0e} of the state in "
                f"ln({HORIZON_TOL:.0e}/{DELTA0:.1e})/lambda)")


def horizon(folder: Path, names: tuple[str, ...]) -> Horizon:
    """The largest exponent in the ``exponent_per_s`` column of the files ``names`` in ``folder``.

    Parameters
    ----------
    folder : Path
        The run's results folder of the scene.
    names : tuple of str
        Files to read (the first that exists and has the column), each ``NAME`` (the column
        ``exponent_per_s``) or ``NAME:COLUMN``; rows whose ``chaotic`` column is ``False`` (a
        separation that did not grow exponentially) are left out unless all are.

    Returns
    -------
    Horizon
        NaN exponent when none is found.
    """
    for entry in names:
        name, _, column = entry.partition(":")
        column = column or "exponent_per_s"
        try:
            with open(folder / name, newline="") as fh:
                rows = [r for r in csv.DictReader(fh) if r.get(column)]
        except OSError:
            continue
        chaotic_rows = [r for r in rows if r.get("chaotic", "True") == "True"] or rows  # fits of a chaotic separation
        values = [v for v in (_float(r[column]) for r in chaotic_rows) if math.isfinite(v)]
        if values:
            return Horizon(max(values), name)
    return Horizon()


def _float(s: str) -> float:
    try:
        return float(s)
    except ValueError:
        return math.nan


@dataclass(slots=True)
class _File:
    """One file's comparison in progress."""

    scene: str
    stage: str
    name: str
    spec: Reproduction
    horizon: Horizon
    rows: list[Row] = field(default_factory=list)

    def add(self, status: str, quantity: str = "", reference: str = "", run: str = "", note: str = "") -> None:
        self.rows.append(Row(self.scene, self.stage, self.name, status, quantity, _cut(reference), _cut(run), note))

    def note(self, rule: Rule) -> str:
        if rule.kind == CHAOTIC:
            return f"{rule.why}; chaotic: {self.horizon.text()}"
        return rule.why


def _cut(s: str, n: int = 80) -> str:
    s = s.strip()
    return s if len(s) <= n else s[: n - 3] + "..."


def _close(a: str, b: str, rule: Rule) -> bool:
    """Whether two cells (or lines) agree within a ``within`` rule's tolerance."""
    if a == b or one_unit_apart(a, b):
        return True
    x, y = _decimal(a), _decimal(b)
    if x is None or y is None:
        na, nb = NUMBER.findall(a), NUMBER.findall(b)
        if not na or len(na) != len(nb) or NUMBER.sub("#", a) != NUMBER.sub("#", b):
            return False
        return all(_close(u, v, rule) for u, v in zip(na, nb, strict=True))
    x, y = float(x), float(y)
    if abs(x - y) <= rule.atol + rule.rtol * abs(x):
        return True
    return (bool(rule.factor) and x != 0 and y != 0 and (x > 0) == (y > 0)
            and max(x / y, y / x) <= rule.factor * (1 + 1e-12))  # 1e-10 / 1e-11 is 10.000000000000002


NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _decimal(s: str) -> Decimal | None:
    try:
        d = Decimal(s.strip())
    except InvalidOperation:
        return None
    return d if d.is_finite() else None


INTEGER = re.compile(r"[-+]?\d+")


def one_unit_apart(a: str, b: str) -> bool:
    """Whether two numbers as written differ by at most one unit of the finer one's last significant
    digit (a value at a rounding boundary), or two texts only in such numbers. Integers (counts) must
    be equal.

    Parameters
    ----------
    a, b : str
        A cell, or a line of text.

    Returns
    -------
    bool

    Examples
    --------
    >>> one_unit_apart("0.39899", "0.39900"), one_unit_apart("0.39899", "0.399213"), one_unit_apart("1e-10", "1e-09")
    (True, False, False)
    >>> one_unit_apart("5.78600e-01", "5.78700e-01"), one_unit_apart("5.00000e-01", "5.78600e-01")
    (True, False)
    >>> one_unit_apart("| 500 | 775.2 | x |", "| 500 | 775.3 | x |"), one_unit_apart("84 impacts", "85 impacts")
    (True, False)
    """
    x, y = _decimal(a), _decimal(b)
    if x is not None and y is not None:
        if INTEGER.fullmatch(a.strip()) or INTEGER.fullmatch(b.strip()):
            return x == y
        if x == y:
            return True
        exponent = min(v.normalize().as_tuple().exponent for v in (x, y) if v != 0)
        return abs(x - y) <= Decimal(1).scaleb(exponent)
    na, nb = NUMBER.findall(a), NUMBER.findall(b)
    if not na or len(na) != len(nb) or NUMBER.sub("#", a) != NUMBER.sub("#", b):
        return False
    return all(u == v or one_unit_apart(u, v) for u, v in zip(na, nb, strict=True))


def _judge(f: _File, rule: Rule, quantity: str, ref: str, run: str) -> None:
    """A differing value: a failure, or within tolerance, or chaotic/sensitive with its note."""
    if rule.kind == EXACT and one_unit_apart(ref, run):
        f.add(LAST_DIGIT, quantity, ref, run, "one unit apart in the last digit written: a value at a rounding "
              "boundary")
    elif rule.kind == EXACT:
        f.add(DIFFERS, quantity, ref, run, rule.why or "deterministic: written to the digits that reproduce")
    elif rule.kind == WITHIN_KIND:
        ok = _close(ref, run, rule)
        f.add(WITHIN if ok else DIFFERS, quantity, ref, run, f"{rule.why} ({rule.tolerance()})")
    else:
        f.add(CHAOTIC_DIFF if rule.kind == CHAOTIC else SENSITIVE_DIFF, quantity, ref, run, f.note(rule))


def _read_csv(path: Path) -> list[list[str]]:
    with open(path, newline="") as fh:
        return list(csv.reader(fh))


def _compare_csv(f: _File, ref: Path, run: Path, whole: Rule) -> None:
    """Cell by cell, each cell under the first part rule that covers its column and row (else ``whole``);
    the differing cells of a chaotic or sensitive column are one row of the report."""
    a, b = _read_csv(ref), _read_csv(run)
    parts = f.spec.part_rules(f.name)
    header = a[0] if a else []
    if not a or not b or a[0] != b[0]:
        f.add(DIFFERS, "header", ",".join(a[0] if a else []), ",".join(b[0] if b else []), "the columns differ")
        return

    def rule_of(col: str, row: list[str]) -> Rule:
        return next((r for r in parts if r.covers_part(col, True) and r.covers_row(row)), whole)

    if len(a) != len(b):
        rules = {rule_of(c, r) for c in header for r in a[1:]} or {whole}
        if whole.kind in (CHAOTIC, SENSITIVE):  # the file's rows themselves are declared not reproducible
            f.add(CHAOTIC_DIFF if whole.kind == CHAOTIC else SENSITIVE_DIFF, "rows", str(len(a) - 1),
                  str(len(b) - 1), f.note(whole))
        elif any(r.kind in JUDGED for r in rules):
            f.add(DIFFERS, "rows", str(len(a) - 1), str(len(b) - 1), "the number of rows differs")
        else:
            rule = next(r for r in (*parts, whole) if r in rules)
            f.add(CHAOTIC_DIFF if rule.kind == CHAOTIC else SENSITIVE_DIFF, "rows", str(len(a) - 1),
                  str(len(b) - 1), f.note(rule))
        return
    firsts = [r[0] for r in a[1:] if r]
    repeated = {v for v in firsts if firsts.count(v) > 1}
    differing = 0
    for j, col in enumerate(header):
        grouped: dict[Rule, list[tuple[int, str, str]]] = {}
        for i, (ra, rb) in enumerate(zip(a[1:], b[1:], strict=True), start=1):
            x, y = (ra[j] if j < len(ra) else ""), (rb[j] if j < len(rb) else "")
            if x != y:
                grouped.setdefault(rule_of(col, ra), []).append((i, x, y))
        for rule, cells in grouped.items():
            differing += len(cells)
            if rule.kind in (CHAOTIC, SENSITIVE):
                i, x, y = cells[0]
                f.add(CHAOTIC_DIFF if rule.kind == CHAOTIC else SENSITIVE_DIFF, f"{col}: {len(cells)} of {len(a) - 1} "
                      f"rows", f"{x} [{_key(header, a[i], repeated)}]", y, f.note(rule))
                continue
            for i, x, y in cells:
                _judge(f, rule, f"{col} [{_key(header, a[i], repeated)}]", x, y)
    if not differing:
        f.add(REPRODUCED, note="the same cells, written differently")


def _key(header: list[str], row: list[str], repeated: set[str]) -> str:
    """The row as the report names it: its first column, and its second when the first repeats (a label
    such as ``state`` or ``level``) in the file."""
    k = f"{header[0]}={row[0]}" if row else ""
    if len(header) > 1 and len(row) > 1 and row[0] in repeated:
        k += f", {header[1]}={row[1]}"
    return k


def _compare_text(f: _File, ref: Path, run: Path, whole: Rule) -> None:
    a = ref.read_text(encoding="utf-8", errors="replace").splitlines()
    b = run.read_text(encoding="utf-8", errors="replace").splitlines()
    parts = f.spec.part_rules(f.name)

    def rule_of(line: str) -> Rule:
        return next((r for r in parts if r.covers_part(line, False)), whole)

    if a == b:
        f.add(REPRODUCED)
        return
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
        if tag == "equal":
            continue
        n = max(i2 - i1, j2 - j1)
        for k in range(n):
            x = a[i1 + k] if i1 + k < i2 else ""
            y = b[j1 + k] if j1 + k < j2 else ""
            if x == y:  # blank lines paired inside a block that differs
                continue
            rules = [rule_of(s) for s in (x, y) if s]
            rule = next((r for r in rules if r.kind in JUDGED), rules[0])  # a judged line on either side decides
            _judge(f, rule, f"line {i1 + k + 1}", x, y)


def compare_file(scene: str, stage: str, name: str, ref_dir: Path, run_dir: Path, spec: Reproduction,
                 hz: Horizon) -> list[Row]:
    """The report's rows for one file of a stage: its whole-file status or one row per differing quantity.

    Parameters
    ----------
    scene, stage, name : str
        The scene, the stage that wrote the file, the file's name.
    ref_dir, run_dir : Path
        The reference folder and the run's folder of the scene.
    spec : Reproduction
        The stage's rules.
    hz : Horizon
        The run's predictability horizon (for chaotic quantities).

    Returns
    -------
    list of Row
    """
    f = _File(scene, stage, name, spec, hz)
    whole = spec.whole(name)
    ref, run = ref_dir / name, run_dir / name
    if whole.kind == RECORD:
        return []
    if not run.exists():
        if ref.exists():
            f.add(MISSING, note="in the reference, not written by the run")
        return f.rows
    if not ref.exists():
        f.add(NEW, note="not in the reference")
        return f.rows
    if whole.kind == FIGURE:
        f.add(EXISTS)
        return f.rows
    if ref.read_bytes() == run.read_bytes():
        f.add(REPRODUCED)
    elif name.endswith(".csv"):
        _compare_csv(f, ref, run, whole)
    else:
        try:
            _compare_text(f, ref, run, whole)
        except UnicodeDecodeError:
            _judge(f, whole, "bytes", f"{ref.stat().st_size} bytes", f"{run.stat().st_size} bytes")
    return f.rows


def _stage_files(folder: Path) -> dict[str, list[str]]:
    """The files each stage wrote into ``folder``, from its ``provenance.json`` ({} if none)."""
    try:
        prov = json.loads((folder / "provenance.json").read_text())
    except (OSError, ValueError):
        return {}
    return {s: list(v.get("files", [])) for s, v in prov.get("stages", {}).items()}


def compare_scene(scene: str, run_dir: Path, ref_dir: Path, specs: dict[str, Reproduction],
                  stages: tuple[str, ...]) -> list[Row]:
    """Every file the scene's stages wrote in the run, against the reference, in pipeline order.

    Parameters
    ----------
    scene : str
        The scene's name.
    run_dir, ref_dir : Path
        The run's results folder and the reference folder of the scene.
    specs : dict of str to Reproduction
        Each stage's rules (stages without an entry use :data:`DEFAULT_RULES`).
    stages : tuple of str
        The stages the scene asks for, in pipeline order.

    Returns
    -------
    list of Row
        A :data:`NO_REFERENCE` row when ``ref_dir`` does not exist.
    """
    if not ref_dir.is_dir():
        return [Row(scene, "-", "", NO_REFERENCE, note=f"{ref_dir} does not exist")]
    run_files, ref_files = _stage_files(run_dir), _stage_files(ref_dir)
    rows = compare_file(scene, "folder", "scene.toml", ref_dir, run_dir, Reproduction(), Horizon())
    for stage in stages:
        spec = specs.get(stage, Reproduction())
        hz = horizon(run_dir, spec.lyapunov)
        names = sorted(set(run_files.get(stage, [])) | set(ref_files.get(stage, [])))
        for name in names:
            if not (ref_dir / name).exists() and name not in run_files.get(stage, []):
                continue  # listed by the reference's provenance, but not committed (.gitignore)
            if not (ref_dir / name).exists() and spec.whole(name).kind in (RECORD,):
                continue
            rows += compare_file(scene, stage, name, ref_dir, run_dir, spec, hz)
    return rows


def failed(rows: list[Row]) -> list[Row]:
    """The rows that make the run fail: a deterministic quantity that differs, a file the run did not write.

    Parameters
    ----------
    rows : list of Row
        The report.

    Returns
    -------
    list of Row
    """
    return [r for r in rows if r.status in FAILURES]


def _counts(rows: list[Row]) -> dict[str, int]:
    out: dict[str, int] = {}
    for r in rows:
        out[r.status] = out.get(r.status, 0) + 1
    return out


def summary(rows: list[Row], report: Path | None = None) -> str:
    """A few lines for the terminal: the counts, each failure (at most 10), where the report is.

    Parameters
    ----------
    rows : list of Row
        The report.
    report : Path, optional
        The report's Markdown file, named in the last line.

    Returns
    -------
    str
    """
    c = _counts(rows)
    bad = failed(rows)
    order = (REPRODUCED, LAST_DIGIT, WITHIN, CHAOTIC_DIFF, SENSITIVE_DIFF, EXISTS, NEW, NO_REFERENCE, DIFFERS, MISSING)
    head = ("reproduction: FAILED" if bad else "reproduction: passed") + " (" + ", ".join(
        f"{c[s]} {s}" for s in order if c.get(s)) + ")"
    lines = [head]
    for r in bad[:10]:
        what = f" {r.quantity}" if r.quantity else ""
        vals = f": reference {r.reference!r}, run {r.run!r}" if (r.reference or r.run) else f": {r.note}"
        lines.append(f"  {r.status} {r.scene}/{r.file}{what}{vals}")
    if len(bad) > 10:
        lines.append(f"  ... and {len(bad) - 10} more")
    if report is not None:
        lines.append(f"  report: {report}")
    return "\n".join(lines)


def _md_cell(s: str) -> str:
    return s.replace("|", "\\|").replace("\n", " ")


def write_report(rows: list[Row], folder: Path, reference: Path) -> Path:
    """``reproduction.md`` (per scene and stage: what reproduced, what differs and why) and ``reproduction.csv``.

    Parameters
    ----------
    rows : list of Row
        The report.
    folder : Path
        Where both files go (the run's parent folder).
    reference : Path
        The reference's parent folder, named in the text.

    Returns
    -------
    Path
        The Markdown file.
    """
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "reproduction.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["scene", "stage", "file", "status", "quantity", "reference", "run", "note"])
        for r in rows:
            w.writerow([r.scene, r.stage, r.file, r.status, r.quantity, r.reference, r.run, r.note])
    bad = failed(rows)
    lines = ["# Reproduction report", "",
             f"The run in `{folder}` against the reference `{reference}` (by default the committed results/), stage "
             "by stage (rules: `bearingshaft/reproduction.py` and each stage's `REPRODUCTION`). Deterministic numbers "
             "are compared to the digits they are written with; quantities of chaotic motion are reported with the "
             "run's predictability horizon; figures are checked to exist; run records (provenance, timings) are "
             "not compared. Every cell is in `reproduction.csv`.", "",
             f"**{'FAILED' if bad else 'Passed'}**: " + ", ".join(f"{n} {s}" for s, n in sorted(_counts(rows).items())),
             ""]
    if bad:
        lines += ["## Failures", "", "| scene | file | quantity | reference | run | note |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {r.scene} | {r.file} | {_md_cell(r.quantity)} | {_md_cell(r.reference)} | {_md_cell(r.run)} | "
                  f"{_md_cell(r.note)} |" for r in bad]
        lines.append("")
    scenes = list(dict.fromkeys(r.scene for r in rows))
    for scene in scenes:
        lines += [f"## {scene}", "", "| stage | file | status | quantity | reference | run | note |",
                  "|---|---|---|---|---|---|---|"]
        listed: dict[tuple[str, str, str], int] = {}
        for r in (r for r in rows if r.scene == scene):
            key = (r.file, r.status, r.quantity.split(" [")[0])
            listed[key] = listed.get(key, 0) + 1
            if listed[key] == MAX_CELLS_LISTED + 1:
                lines.append(f"| {r.stage} | {r.file} | {r.status} | ... | | | more in reproduction.csv |")
            if listed[key] > MAX_CELLS_LISTED:
                continue
            lines.append(f"| {r.stage} | {r.file} | {r.status} | {_md_cell(r.quantity)} | {_md_cell(r.reference)} | "
                         f"{_md_cell(r.run)} | {_md_cell(r.note)} |")
        lines.append("")
    path = folder / "reproduction.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
