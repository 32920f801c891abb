"""The examples in the docstrings of the pure helpers run as tests (formatting, parsing, case ids)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import bearingshaft
import reduced

# every module of bearingshaft and reduced (those without examples pass trivially)
MODULES = sorted(
    {m.name for m in pkgutil.walk_packages(bearingshaft.__path__, "bearingshaft.")}
    | {m.name for m in pkgutil.walk_packages(reduced.__path__, "reduced.")}
)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed"


def test_the_examples_are_found():
    # a guard on the collection: the formatting helpers' examples must be among those run
    finder = doctest.DocTestFinder()
    tests = finder.find(importlib.import_module("bearingshaft.digits"))
    assert sum(len(t.examples) for t in tests) >= 9
