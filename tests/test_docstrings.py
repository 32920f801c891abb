"""Public functions and classes carry numpydoc sections (STYLE.md section 9), read from the source with ast.

Checked: every public module-level function that takes at least one argument, and every public
module-level class, in every module of geometry/, fem/, reduced/ and bearingshaft/ (private
modules such as ``fem/_pardiso.py`` included: their public names are used across packages).

- a function's docstring has a ``Parameters`` section (a ``Parameters`` line underlined with
  dashes), and every argument of its signature (``*args`` and ``**kwargs`` too) is named in it,
  alone or in a group such as ``K, M : (n, n) sparse matrix``;
- a class's docstring has a ``Parameters`` or an ``Attributes`` section.

Exempt:

- private names (a leading underscore), the numba kernels among them (``_exact_kernel`` ...);
  methods are not read (module-level definitions only);
- functions without arguments (nothing to describe; their first line says what they return);
- exception classes (a base named ``...Error`` or ``...Exception``) whose body is their docstring
  alone: they take one message, which their docstring describes;
- the re-exports of the ``__init__.py`` files: they are imports, not definitions, so the reader
  does not see them (each name is checked in the module that defines it; a function or class
  defined in an ``__init__.py`` is checked like any other);
- the command-line entry points ``main(argv)``, whose arguments are described by ``--help``.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("geometry", "fem", "reduced", "bearingshaft")
EXEMPT_FUNCTIONS = ("main",)  # CLI entry points: main(argv=None) -> int
SECTION = r"^{}\n-{{3,}}$"  # a numpydoc heading: the name, then a line of dashes


def _definitions():
    """(label, node) of every checked public module-level function and class."""
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for node in ast.parse(path.read_text(encoding="utf-8")).body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) \
                        and not node.name.startswith("_"):
                    yield f"{path.relative_to(ROOT)}:{node.lineno} {node.name}", node


@functools.cache
def _all_definitions() -> list:
    """Every checked definition, read on first use, not at collection: under pytest-xdist each worker collects
    every file, and the worker that does not run this one would parse the four packages for nothing (issue 28)."""
    return list(_definitions())


def _arguments(node: ast.FunctionDef) -> list[str]:
    a = node.args
    names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    names += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
    return names


def _plain_exception(node: ast.ClassDef) -> bool:
    """An exception class with nothing but a docstring (it takes the message only)."""
    bases = [b.id if isinstance(b, ast.Name) else b.attr if isinstance(b, ast.Attribute) else "" for b in node.bases]
    return any(b.endswith(("Error", "Exception")) for b in bases) and len(node.body) == 1 \
        and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)


def _has_section(doc: str, name: str) -> bool:
    return re.search(SECTION.format(name), doc, re.M) is not None


def _documented_names(doc: str) -> set[str]:
    """The names a Parameters section describes: its unindented lines up to ' : ' (or the line)."""
    m = re.search(SECTION.format("Parameters") + r"\n(.*?)(?=^\S[^\n]*\n-{3,}$|\Z)", doc, re.M | re.S)
    names: set[str] = set()
    for line in (m.group(1) if m else "").splitlines():
        if line and not line[0].isspace():
            names |= {n.strip().lstrip("*") for n in line.split(" : ")[0].split(",")}
    return names


def _functions(definitions):
    return [(label, node) for label, node in definitions if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and _arguments(node) and node.name not in EXEMPT_FUNCTIONS]


def _violations(definitions) -> dict[str, list[str]]:
    """The definitions that break each rule (module docstring), by rule."""
    out: dict[str, list[str]] = {"no_parameters": [], "undescribed": [], "class": []}
    for label, node in _functions(definitions):
        doc = ast.get_docstring(node) or ""
        if not _has_section(doc, "Parameters"):
            out["no_parameters"].append(label)
            continue
        missing = [a for a in _arguments(node) if a not in _documented_names(doc)]
        if missing:
            out["undescribed"].append(f"{label}: {', '.join(missing)}")
    out["class"] = [label for label, node in definitions
                    if isinstance(node, ast.ClassDef) and not _plain_exception(node)
                    and not any(_has_section(ast.get_docstring(node) or "", s) for s in ("Parameters", "Attributes"))]
    return out


@functools.cache
def _all_violations() -> dict:
    return _violations(_all_definitions())


def test_the_definitions_are_found():
    # a guard on the reader: the four packages hold hundreds of public definitions, known ones among them
    assert len(_all_definitions()) > 300
    names = {node.name for _, node in _all_definitions()}
    assert {"build_mesh", "modal_analysis", "craig_bampton", "AssemblyGeometry"} <= names


def test_functions_have_a_parameters_section():
    bad = _all_violations()["no_parameters"]
    assert not bad, f"{len(bad)} public functions without a numpydoc Parameters section:\n" + "\n".join(bad)


def test_every_argument_is_described():
    bad = _all_violations()["undescribed"]
    assert not bad, "arguments missing from the Parameters section:\n" + "\n".join(bad)


def test_classes_have_a_parameters_or_attributes_section():
    bad = _all_violations()["class"]
    assert not bad, f"{len(bad)} public classes without a Parameters or Attributes section:\n" + "\n".join(bad)


PLANTED = '''
def bare(x):
    """One line only."""


def partial(K, M, *extra, tol=1e-9, **options):
    """Parameters: K and M (a heading without dashes is not a section).

    Parameters
    ----------
    K, M : (n, n) ndarray
        N/m and kg.
    **options
        Passed on.
    """


def described(K, M, tol=0.0):
    """Solve (``tol`` is named under Returns only).

    Parameters
    ----------
    K, M : (n, n) ndarray
        N/m and kg.

    Returns
    -------
    tol : float
    """


def main(argv=None):
    """Command line."""


def _kernel(x):
    pass


class Plain:
    """No section."""


class Fine:
    """Has one.

    Attributes
    ----------
    x : float
    """


class Refused(ValueError):
    """A message alone."""
'''


def test_the_checks_can_fail():
    # the rules on a planted module: each kind of violation is found, and only those
    defs = [(node.name, node) for node in ast.parse(PLANTED).body if not node.name.startswith("_")]
    v = _violations(defs)
    assert v["no_parameters"] == ["bare"]
    # a name under another section does not count as described
    assert v["undescribed"] == ["partial: tol, extra", "described: tol"]
    assert v["class"] == ["Plain"]
    # the readers themselves: a heading without dashes is not a section
    doc = "Sum.\n\nParameters\n----------\na, b : float\n    m.\n*args : tuple\n\nReturns\n-------\nfloat\n"
    assert _has_section(doc, "Parameters") and _has_section(doc, "Returns")
    assert _documented_names(doc) == {"a", "b", "args"}
    assert not _has_section("Sum.\n\nParameters: a and b.\n", "Parameters")
    assert _documented_names("Sum.\n\nReturns\n-------\nfloat\n") == set()
    assert not _plain_exception(ast.parse('class E(ValueError):\n    """Bad."""\n    code: int\n').body[0])
