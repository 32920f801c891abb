"""Errors of the scene schema and the helpers that word them: one line, naming the file, table and key."""

from __future__ import annotations

import difflib

from reduced._checks import show  # noqa: F401  (re-exported: a value cut to one short line, as every message shows it)


class SceneError(ValueError):
    """A scene that cannot be read or is invalid; the message is one line."""


def suggest(word: str, known) -> str:
    """' (did you mean X?)' for the closest of ``known`` to a misspelled ``word``, else ''.

    Parameters
    ----------
    word : str
        The word given.
    known : iterable of str
        The words allowed.

    Returns
    -------
    str
    """
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""




class SweepError(SceneError):
    """A sweep that cannot run as given; one line, exit code 2."""
