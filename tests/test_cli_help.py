"""Every help text the command line prints: ``bearingshaft --help`` and each subcommand's ``--help``
(argparse expands ``%`` in help strings, so a literal one must be written ``%%``: an unescaped
"95 % intervals" made the top-level help raise a TypeError)."""

from __future__ import annotations

import argparse
import contextlib
import io

import pytest

from bearingshaft import cli


def _subcommands() -> list[str]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sorted(sub.choices)


def _help(argv: list[str]) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as exc:
        cli.build_parser().parse_args(argv)
    assert exc.value.code == 0
    return out.getvalue()


def test_the_top_level_help_lists_every_subcommand():
    text = _help(["--help"])
    names = _subcommands()
    assert len(names) >= 10  # the pipeline's subcommands (mesh ... identify), not an empty parser
    for name in names:
        assert name in text


@pytest.mark.parametrize("name", _subcommands())
def test_each_subcommand_prints_its_help(name):
    text = _help([name, "--help"])
    assert text.startswith("usage:") and name in text.splitlines()[0]
