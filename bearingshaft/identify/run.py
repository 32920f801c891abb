"""The model runs of a fit on Dask: the cluster as ``bearingshaft sweep`` has it, the problem shipped once.

:func:`dask_evaluator` opens a client by :func:`bearingshaft.sweep.run.dask_client` (a
:class:`distributed.LocalCluster` of single-threaded worker processes, one per core, or the
scheduler at an address), warms the workers up (numba's kernels loaded,
:func:`bearingshaft.sweep.run.warm_up`), and scatters the :class:`~bearingshaft.identify.problem.Problem`
(the reduced apparatus, the test) to every worker once; each pass's
:class:`~bearingshaft.identify.residuals.Target` (the test's channels) is scattered once too. A
batch of trial points (a point and its finite-difference neighbours) is then one task each.
"""

from __future__ import annotations

import contextlib

from bearingshaft.identify.problem import Problem, channels_at, evaluate
from bearingshaft.sweep.run import dask_client, warm_up


class DaskEvaluator:
    """Model runs as Dask tasks (:class:`bearingshaft.identify.fit.SerialEvaluator`'s interface).

    Parameters
    ----------
    client : distributed.Client
    problem : Problem
    where : str
        Where the tasks run, in words.
    """

    def __init__(self, client, problem: Problem, where: str) -> None:
        self.client = client
        self.problem = client.scatter(problem, broadcast=True, hash=False)
        self.where = where
        self.workers = len(client.nthreads())

    def put(self, target):
        """The target on every worker (a future)."""
        return self.client.scatter(target, broadcast=True, hash=False)

    def map(self, target, thetas) -> list:
        """The evaluations at ``thetas``, in order (one task each)."""
        futures = [self.client.submit(evaluate, self.problem, target, th, pure=False) for th in thetas]
        return self.client.gather(futures)

    def scatter(self, target, theta, points, draws: int) -> list:
        """The point with its noise variances, then the cloud's points with the force redrawn (one task each)."""
        futures = [self.client.submit(evaluate, self.problem, target, theta, noise_draws=draws, pure=False),
                   *[self.client.submit(evaluate, self.problem, target, q, force_seed=k + 1, pure=False)
                     for k, q in enumerate(points)]]
        return self.client.gather(futures)

    def records(self, thetas) -> list:
        """(t, data) of the compared channels at ``thetas`` (one task each)."""
        return self.client.gather([self.client.submit(channels_at, self.problem, th, pure=False) for th in thetas])


@contextlib.contextmanager
def dask_evaluator(problem: Problem, scheduler: str | None = None, workers: int | None = None):
    """A :class:`DaskEvaluator` on a LocalCluster (or ``scheduler``), closed on exit.

    Parameters
    ----------
    problem : Problem
    scheduler : str, optional
        A running scheduler's address (``tcp://host:8786``).
    workers : int, optional
        LocalCluster worker processes (default: one per core).

    Returns
    -------
    A context manager of DaskEvaluator.
    """
    with dask_client(scheduler, workers) as (client, where):
        client.run(warm_up)
        yield DaskEvaluator(client, problem, where)


__all__ = ["DaskEvaluator", "dask_evaluator"]
