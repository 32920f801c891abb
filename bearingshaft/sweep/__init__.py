"""Parameter sweeps of any scene on Dask (issue 13): ``bearingshaft sweep``.

A sweep runs one scene over a design of parameter values. The values come from a
``[sweep]`` table in the scene or from ``--vary`` on the command line::

    [sweep]
    design = "grid"                    # grid (product) | zip (i-th of each) | random (Latin hypercube)
    samples = 0                        # random: number of cases
    seed = 0                           # random: seed of the Latin hypercube
    plots = ["freq_early_hz"]          # metrics drawn (default: a standard set the stages have)
    x = ""                             # plot against this metric column instead of the varied key
    overlay = ""                       # "nnm_stability": NNM 1 and 3 Floquet stability beside the plot
    [sweep.vary]
    "model.gap" = "1e-4:1e-3:9:log"      # LO:HI:N (linear), LO:HI:N:log; random design: LO:HI[:log]
    "model.k_g" = [1e7, 1e8, 1e9]      # or a list (CLI: 1e7,1e8,1e9)
    "initial.v0_m_s[1]" = [1.0, 2.0]   # an element of a list key
    "load[0].peak_N" = [100.0, 500.0]  # a key of the first [[load]]

Keys are ``TABLE.KEY`` as in the scene, in the scene's units. The table is read by the scene
parser (:mod:`bearingshaft.scenes.sweep`); this package plans, runs and writes the sweep, in
the order of its modules:

- :mod:`~bearingshaft.sweep.plan`: the design's points and the cases. Every case's scene is
  written out (TOML), read back by the scene parser and its memory checked
  (:mod:`bearingshaft.budget`) before anything runs: one bad value refuses the whole sweep in
  one line naming the key, with exit code 2. The case id is the first 12 hex digits of the
  sha256 of the case's values.
- :mod:`~bearingshaft.sweep.metrics`: a finished case's row of scalar metrics, read from the
  stage's own output (``provenance.json`` statistics and the files the stage wrote), and the
  NNM stability overlay (shooting over the swept energies).
- :mod:`~bearingshaft.sweep.run`: the cases on Dask, a :class:`distributed.LocalCluster` with
  one single-threaded worker process per core (``--workers N`` to limit), started and closed
  by the sweep, or the scheduler at ``--scheduler ADDRESS``. Each case runs the scene's stages
  through :func:`bearingshaft.pipeline.run_stage`, the code of a single run, into
  ``<out>/<case-id>/`` (default ``runs/<scene>/sweep/``; ``--update-reference``: the committed
  ``results/<scene>/sweep/``). A rerun skips cases whose folder
  is complete (every stage in its ``provenance.json``, written last by
  :mod:`bearingshaft.output`, and its ``scene.toml`` equal to the case's); a failing case (a
  solver error, a value refused by a stage, a worker lost more often than Dask's
  ``allowed-failures``) is a row with its one-line message, never the end of the sweep. A
  worker killed mid-case has its task rerun elsewhere by Dask; the folder of a case is written
  whole or not at all, so nothing is lost or doubled. A reduced model (``[model] kind =
  "rom"``) is built once before the sweep (for each distinct reduction: contact and damping do
  not change it), scattered to the workers once, and each worker puts it into its
  reduced-model cache, from where every case's stages read it; the ``reduce`` stage is not
  repeated per case.
- :mod:`~bearingshaft.sweep.tables`: the rows to ``sweep.parquet`` and ``sweep.csv`` in
  ``<out>``, the overlay to ``nnm_stability.csv``, ``sweep_provenance.json`` and
  ``sweep_scene.toml``; :mod:`~bearingshaft.sweep.report` draws ``sweep.png`` and
  ``symmetry_break.png`` (figures only, no solver).
- :mod:`~bearingshaft.sweep.command`: the ``sweep`` subcommand's arguments.

The names below are re-exported here for ``from bearingshaft.sweep import ...``.
"""

from bearingshaft.scenes.sweep import (
    SweepError,
    SweepSpec,
    Vary,
    parse_sweep_table,
    parse_values,
    parse_vary_option,
)
from bearingshaft.sweep.command import spec_from_args, sweep_command, sweep_source
from bearingshaft.sweep.metrics import (
    NnmStability,
    case_metrics,
    frc_metrics,
    hammer_metrics,
    nnm_stability,
    ringdown_metrics,
)
from bearingshaft.sweep.plan import (
    Case,
    SweepPlan,
    apply_values,
    base_value,
    build_plan,
    case_id,
    case_stages,
    design_points,
)
from bearingshaft.sweep.run import case_complete, dask_client, local_cores, run_case, run_sweep
from bearingshaft.sweep.tables import SweepResult, write_results, write_tables
from reduced.transient.spectral import dominant_freq_hz

__all__ = ["SweepSpec", "Vary", "Case", "SweepPlan", "SweepResult", "SweepError", "NnmStability", "parse_sweep_table",
           "parse_values", "parse_vary_option", "design_points", "case_id", "apply_values", "base_value",
           "case_stages", "build_plan", "dask_client", "local_cores", "run_sweep", "run_case", "case_complete",
           "case_metrics", "ringdown_metrics", "hammer_metrics", "frc_metrics", "nnm_stability", "dominant_freq_hz",
           "write_tables", "write_results", "spec_from_args", "sweep_source", "sweep_command"]
