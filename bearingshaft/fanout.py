"""Independent pieces of a stage, serially or as tasks of the job's cluster (issue 28).

A stage hands its independent pieces (the levels of an FRC, the branches of an FEP, the blows of a
hammer test) to :func:`fan_out`. By default they run here, one after the other; a job that runs the
stage as a task of a Dask cluster (:func:`bearingshaft.jobs.run_task`) installs a mapper with
:func:`mapping` that submits them to the same cluster, so a long stage uses every worker. The stage
does not know which: the results come back in the order of the pieces either way, and each piece
sets its own single-thread BLAS and warning filters (:func:`piece`), so the numbers are the same
bits on one process or on several. This module imports no Dask: the mapper comes from the job.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import warnings
from collections.abc import Callable, Iterator, Sequence

_MAPPER: contextvars.ContextVar = contextvars.ContextVar("bearingshaft_fanout_mapper", default=None)


def _serial(fn: Callable, items: Sequence) -> list:
    return [fn(x) for x in items]


@contextlib.contextmanager
def mapping(mapper: Callable[[Callable, Sequence], list] | None) -> Iterator[None]:
    """Context in which :func:`fan_out` hands its pieces to ``mapper`` (None: serially, here).

    Parameters
    ----------
    mapper : callable or None
        ``mapper(fn, items) -> [fn(item) for item in items]``, in that order, wherever it runs them.
    """
    token = _MAPPER.set(mapper)
    try:
        yield
    finally:
        _MAPPER.reset(token)


def piece(fn: Callable, item):
    """``fn(item)`` on one BLAS thread with warnings silenced, as the stages run their algebra (a piece
    on another worker starts from that worker's state, not the stage's).

    Parameters
    ----------
    fn : callable
        A module-level function (it may be pickled to another process).
    item : its argument

    Returns
    -------
    ``fn(item)``
    """
    from reduced._blas import single_thread_blas

    with single_thread_blas(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # LinAlgWarning from LU on rejected continuation steps
        return fn(item)


def fan_out(fn: Callable, items: Sequence) -> list:
    """``[fn(item) for item in items]``, on the job's cluster when the stage runs in one, else here.

    Parameters
    ----------
    fn : callable
        A module-level function of one argument (picklable, as its argument and result must be).
        Each call runs inside :func:`piece`.
    items : sequence
        The independent pieces.

    Returns
    -------
    list
        The results in the order of ``items``.

    Examples
    --------
    >>> fan_out(abs, [-1, 2, -3])
    [1, 2, 3]
    """
    items = list(items)
    mapper = _MAPPER.get()
    call = functools.partial(piece, fn)
    if mapper is None or len(items) < 2:
        return _serial(call, items)
    return list(mapper(call, items))


__all__ = ["fan_out", "mapping", "piece"]
