"""Speed of the ringdown integrators (issue 14), every ratio against a named baseline in the same process.

    PYTHONPATH=. python benchmarks/integrator_speed.py [--repeats 5] [--baseline-commit fc521a5]
        [--hammer-modes 60 120] [--no-dop853-2s] [--out results/performance] [--explicit-only] [--processes 5]

The whole measurement runs in ``--processes`` child processes (default 5), one after the other, and each
headline row is that of the median process (:func:`in_processes`; benchmarks/process_median.py: a process of
this machine runs at one of two speeds, so one process draws one). In each process it measures, each a median
of ``--repeats`` wall times (perf_counter; CPU times beside them, as the machine may be shared; the explicit rows
in CPU time, wall beside):

1. the exact integrator on the 2 s ``discrete-impulse`` and ``rom-impulse`` ringdowns (20 kHz), and
   per output sample on the ``hammer-test`` reduced model (apparatus, ``--hammer-modes``
   fixed-interface modes; a 20 N, 1 ms blow at 10 ms that closes no gap; the marginal cost of a
   sample = (t(0.22 s) - t(0.02 s)) / 4000) beside one numpy N x K complex matrix-vector product
   (what a sample must at least cost);
2. the central-difference integrator on the same 2 s ringdowns (steps per second in CPU time, every kernel of a
   scene alternating with the others in one loop, :func:`alternate`; on discrete-impulse the lumped
   kernel against the register kernel it replaced, alternating, and the latency of its dependent path), and on
   rom-impulse the default kernel (jumped in blocks while the contact state holds, issue 28) against the previous
   release's, the step-by-step kernel in the open-gap modal coordinates (its reference, no target) and the
   physical-coordinate kernel, with a roofline line for each (``--explicit-only`` measures just the explicit
   rows and replaces them in the tables);
3. the exact integrator against DOP853 restarted at every crossing (``integrate_dop853(...,
   events=True)``, the independent reference) at equal error: on the 0.2 s window the error is the
   max-norm error of x against the exact run (relative to max |x|); on the 2 s window no
   double-precision method predicts the motion pointwise (a 4e-16 change of v(0) moves x by 20 %
   of its range by 0.6 s), so there the error is the energy-balance error of each run. DOP853 is
   run at rtol 1e-7 .. 1e-13; its time at an error is that of the fastest rtol that reaches it.

Everything runs on one BLAS thread (:func:`reduced._blas.single_thread_blas`, as the stages run the
integrators): on a shared machine BLAS threads make small dense problems hundreds of times slower,
which would flatter the ratios against the baseline.

The baseline of 1 and 2 is the previous release's kernels, the code before issue 14
(``--baseline-commit``, default fc521a5, loaded from git into a temporary module and run on the
same models in the same process); its outputs are compared with
today's (max |difference| over the first 0.2 s, where round-off has not yet been amplified, and
bit for bit for the explicit scheme).

Writes integrator_headline.csv (columns what, ours_s, baseline, baseline_s, ratio = baseline_s /
ours_s, error, target, met: rows that can be concatenated with other headline tables; processes: the per-process
numbers), integrator_processes.csv (every process's headline numbers and speed probe),
integrator_details.csv (every measurement), integrator_dop853.csv (the DOP853 scans),
integrator_machine.csv (machine, versions, load) and integrator_speed.png.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import machine_rows, write_rows  # noqa: E402
from reduced._blas import single_thread_blas  # noqa: E402
from reduced.studies import relative_error  # noqa: E402
from reduced.transient.dop853 import integrate_dop853  # noqa: E402
from reduced.transient.exact import integrate_exact  # noqa: E402
from reduced.transient.exact_tables import clear_table_cache  # noqa: E402
from reduced.transient.explicit import integrate_explicit  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from process_median import children, merge, probe_ms, read_csv  # noqa: E402  (issue 28)

FS = 20000.0  # Hz, the scenes' output rate
LONG_S = 2.0  # s, the ringdowns of the scenes
WINDOW_S = 0.2  # s, the window where the motion is still predictable pointwise
HAMMER_S = (0.02, 0.22)  # s, two records past the blow: their difference is 4000 samples of free motion
HAMMER_BLOW_N = 20.0  # N: closes no gap (hammer-test levels.csv)
DOP_RTOLS_SHORT = (1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13)
DOP_RTOLS_LONG = (1e-8, 1e-9, 1e-10, 1e-11)
ERROR_TARGETS = (1e-6, 1e-8)
TARGET_RATIO = 1000.0  # exact vs DOP853 restarted at crossings, at equal error
RATES = {"discrete-impulse": 5e7, "rom-impulse": 3e7}  # steps/s, the explicit step's targets (issues 14, 28)
BASELINE = "exact, the previous release's kernels ({}), same process"


def load_baseline(commit: str) -> dict:
    """{'exact': module, 'explicit': module} of reduced/transient at ``commit``, from git, in a folder of
    their own; {} when git cannot give them."""
    cache = Path(os.environ.get("BEARINGSHAFT_CACHE", Path.home() / ".cache" / "bearingshaft"))
    folder = cache / f"integrator-baseline-{commit}"
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for name in ("exact", "explicit"):
        path = folder / f"baseline_{name}.py"
        if not path.exists():
            try:
                src = subprocess.run(["git", "show", f"{commit}:reduced/transient/{name}.py"], cwd=ROOT,
                                     capture_output=True, text=True, check=True, timeout=30).stdout
            except (OSError, subprocess.SubprocessError) as exc:
                print(f"no baseline {name} at {commit}: {exc}", flush=True)
                return {}
            # compiled afresh each run: numba's disk cache cannot find a module loaded from a path
            path.write_text(src.replace("cache=True", "cache=False"))
        spec = importlib.util.spec_from_file_location(f"baseline_{name}_{commit}", path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod  # numba's cache finds the module by this name
        spec.loader.exec_module(mod)
        out[name] = mod
    return out


def timed(fn, repeats: int) -> tuple[object, dict]:
    """(last result, {median_s, min_s, max_s, cpu_median_s}) of ``repeats`` calls after one warm-up."""
    fn()
    walls, cpus, res = [], [], None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        res = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return res, {"median_s": float(np.median(walls)), "min_s": float(np.min(walls)), "max_s": float(np.max(walls)),
                 "cpu_median_s": float(np.median(cpus)), "repeats": repeats}


def alternate(fns: dict, repeats: int) -> tuple[dict, dict]:
    """Each of ``fns`` (code -> callable) warmed once, then ``repeats`` rounds in which every one runs once in
    turn: (the last result of each, {code: {median_s, min_s, max_s: CPU seconds (process_time); wall_median_s,
    wall_min_s: wall seconds; repeats}}). The explicit rows are measured this way, every kernel in the same loop,
    so that they share the machine's state (its load, which moves by tens of percent within a minute on a shared
    machine, and the caches) and are compared by CPU time, which a co-scheduled process inflates less than wall
    time."""
    for fn in fns.values():
        fn()
    walls = {c: [] for c in fns}
    cpus = {c: [] for c in fns}
    res = {}
    for _ in range(repeats):
        for c, fn in fns.items():
            c0, t0 = time.process_time(), time.perf_counter()
            res[c] = fn()
            walls[c].append(time.perf_counter() - t0)
            cpus[c].append(time.process_time() - c0)
    return res, {c: {"median_s": float(np.median(cpus[c])), "min_s": float(np.min(cpus[c])),
                     "max_s": float(np.max(cpus[c])), "wall_median_s": float(np.median(walls[c])),
                     "wall_min_s": float(np.min(walls[c])), "repeats": repeats} for c in fns}


def cold(fn):
    """``fn`` with the exact integrator's kept tables forgotten first (:func:`run_tables`): a run that
    works out its tables, as the first run of a system does."""
    def call():
        clear_table_cache()
        return fn()
    return call


def _matvecs(A: np.ndarray, u: np.ndarray, k: int) -> None:
    for _ in range(k):
        A @ u


def scene_model(name: str):
    from bearingshaft.scenes import load_scene
    from bearingshaft.systems import model_system, scene_initial_state

    sc = load_scene(name)
    system, P = model_system(sc.model)
    x0, v0 = scene_initial_state(sc, system, P)
    return system, x0, v0


def head_diff(a, b, fs: float) -> float:
    """max |x_a - x_b| / max |x_b| over the first WINDOW_S."""
    k = int(WINDOW_S * fs) + 1
    return float(np.max(np.abs(a.x[:k] - b.x[:k])) / np.max(np.abs(b.x[:k])))


def exact_rows(base: dict, repeats: int, commit: str, methods=("exact", "explicit")) -> tuple[list[dict], list[dict]]:
    """Headline and detail rows of the exact and explicit 2 s ringdowns (of ``methods``), ours against the
    baseline; the explicit one of discrete-impulse only (rom-impulse's: :func:`reduced_beam_explicit_rows`), ours
    and the baseline alternating (:func:`alternate`), in CPU time."""
    heads, details = [], []
    targets = {("exact", "discrete-impulse"): 0.03, ("exact", "rom-impulse"): 0.4}
    for scene in ("discrete-impulse", "rom-impulse"):
        system, x0, v0 = scene_model(scene)
        kw = {"step_basis": "contact"} if scene == "rom-impulse" else {}
        for method in methods:
            if method == "explicit" and scene == "rom-impulse":
                continue  # reduced_beam_explicit_rows: the default kernel beside the physical and modal ones
            ours = integrate_exact if method == "exact" else integrate_explicit
            opts = {} if method == "exact" else kw
            if method == "explicit":
                res, heads_row, rows = _explicit_row(scene, system, x0, v0, base, commit, repeats)
                heads.append(heads_row)
                details += rows
                print(heads[-1], flush=True)
                continue
            res, t = timed(partial(ours, system, x0, v0, LONG_S, FS, **opts), repeats)
            row = {"scene": scene, "method": method, "code": "ours", **t, "n_events": res.stats.get("n_events", ""),
                   "n_march": res.stats.get("n_march", ""), "n_steps": res.stats.get("n_steps", ""),
                   "energy_balance_error": res.energy_balance_error}
            details.append(row)
            b_res, b_t = None, None
            if method in base:
                mod = base[method]
                fn = mod.integrate_exact if method == "exact" else mod.integrate_explicit
                b_res, b_t = timed(partial(fn, system, x0, v0, LONG_S, FS, **opts), repeats)
                details.append({"scene": scene, "method": method, "code": f"baseline {commit}", **b_t,
                                "n_events": b_res.stats.get("n_events", ""), "n_march": b_res.stats.get("n_march", ""),
                                "n_steps": b_res.stats.get("n_steps", ""),
                                "energy_balance_error": b_res.energy_balance_error})
            if method == "exact":
                _, t_cold = timed(cold(partial(ours, system, x0, v0, LONG_S, FS, **opts)), repeats)
                details.append({"scene": scene, "method": "exact, tables worked out in the run", "code": "ours",
                                **t_cold, "n_events": res.stats.get("n_events", ""),
                                "energy_balance_error": res.energy_balance_error})
                err = f"energy balance {res.energy_balance_error:.2g}"
                if b_res is not None:
                    err += (f" (before: {b_res.energy_balance_error:.2g}); first {WINDOW_S:g} s differs from before "
                            f"by {head_diff(res, b_res, FS):.2g} of max |x|")
                target = targets[(method, scene)]
                heads.append({"what": f"exact ringdown, {scene}, {LONG_S:g} s at {FS:g} Hz "
                                      f"({res.stats['n_events']} events, {res.stats['n_march']} march steps; tables "
                                      f"kept from the warm-up run, worked out in the run: {t_cold['median_s']:.3g} s)",
                              "ours_s": t["median_s"], "baseline": BASELINE.format(commit),
                              "baseline_s": b_t["median_s"] if b_t else "", "ratio": b_t["median_s"] / t["median_s"]
                              if b_t else "", "error": err, "target": f"<= {target:g} s",
                              "met": t["median_s"] <= target})
            print(heads[-1], flush=True)
    return heads, details


def _explicit_row(scene: str, system, x0, v0, base: dict, commit: str, repeats: int) -> tuple:
    """(our run, the headline row, detail rows) of the explicit 2 s ringdown of ``scene`` (discrete-impulse:
    the lumped kernel) against the baseline's, alternating (:func:`alternate`), in CPU time."""
    fns = {"ours": partial(integrate_explicit, system, x0, v0, LONG_S, FS)}
    if "explicit" in base:
        fns["baseline"] = partial(base["explicit"].integrate_explicit, system, x0, v0, LONG_S, FS)
    load0 = os.getloadavg()[0]
    res, t = alternate(fns, repeats)
    load1 = os.getloadavg()[0]
    ours, b_res = res["ours"], res.get("baseline")
    steps = ours.stats["n_steps"]
    details = [{"scene": scene, "method": "explicit", "code": "ours" if c == "ours" else f"baseline {commit}",
                **t[c], "n_steps": steps, "energy_balance_error": res[c].energy_balance_error} for c in fns]
    same = b_res is not None and all(np.array_equal(getattr(ours, k), getattr(b_res, k))
                                     for k in ("x", "v", "dissipated"))
    tc = t["ours"]
    rate = RATES[scene]
    row = {"what": f"explicit (central difference) ringdown, {scene}, {LONG_S:g} s: {steps} steps, "
                   f"{steps / tc['median_s']:.3g} steps/s in CPU time (median of {repeats}, alternating with the "
                   f"baseline; fastest run {steps / tc['min_s']:.3g}; wall time {steps / tc['wall_median_s']:.3g}; "
                   f"machine load (1 min) {load0:.1f} before, {load1:.1f} after, on {os.cpu_count()} cores)",
           "ours_s": tc["median_s"], "baseline": BASELINE.format(commit).replace("exact", "explicit") + ", alternating",
           "baseline_s": t["baseline"]["median_s"] if b_res is not None else "",
           "ratio": t["baseline"]["median_s"] / tc["median_s"] if b_res is not None else "",
           "error": "bit for bit as before" if same else "" if b_res is None else
           f"first {WINDOW_S:g} s differs from before by {head_diff(ours, b_res, FS):.2g} of max |x|; energy balance "
           f"{ours.energy_balance_error:.3g} (before: {b_res.energy_balance_error:.3g})",
           "target": f">= {rate:.0e} steps/s (<= {steps / rate:.3g} s CPU)", "met": steps / tc["median_s"] >= rate}
    return ours, row, details


def _chain_kernel():
    """A numba loop of R rounds of one dependent 12-term dot product and a 12-term update: the latency of
    one such link, the pattern a step repeats (a sum over the coordinates feeding the next update)."""
    import numba as nb

    @nb.njit(fastmath={"reassoc", "contract"})
    def chain(z, u, R):
        for _ in range(R):
            s = 0.0
            for i in range(12):
                s += u[i] * z[i]
            for i in range(12):
                z[i] = z[i] - 1e-9 * s * u[i]
        return z[0]

    return chain


def roofline(n: int, p: int, nu: int, steps_per_cpu_s: float) -> dict:
    """Flops and L1 bytes a step of the modal kernel (no contact, no loads; counted from its loops) against
    the core's measured multiply-add peak (dgemm) and the latency of one dependent sum-and-update link, both
    in CPU time (the machine is shared)."""
    chain = _chain_kernel()
    A, B = np.random.default_rng(0).standard_normal((2, 256, 256))
    z, u = np.ones(12), np.full(12, 0.1)
    chain(z, u, 10)
    t = []
    for _ in range(5):  # the core's multiply-add peak: one-thread BLAS dgemm (the caller holds BLAS to one thread)
        c0 = time.process_time()
        for _ in range(20):
            A @ B
        t.append(time.process_time() - c0)
    peak = 20 * 2.0 * 256**3 / min(t)  # flop/s
    R = 2_000_000
    t = []
    for _ in range(5):
        c0 = time.process_time()
        chain(z, u, R)
        t.append(time.process_time() - c0)
    link = min(t) / R  # s
    flops = n * (9 + 2 * nu + 4 * p) + 6 * p * p + 6 * p + 5
    words = n * (12 + nu + 2 * p) + 3 * p * p + 2 * p  # doubles read or written a step, all in L1
    return {"flops_per_step": flops, "bytes_per_step": 8 * words, "peak_flops_per_s": peak,
            "attained_flops_per_s": flops * steps_per_cpu_s, "fraction_of_peak": flops * steps_per_cpu_s / peak,
            "link_latency_s": link, "links_per_step": 1.0 / (steps_per_cpu_s * link),
            "l1_bytes_per_s": 8 * words * steps_per_cpu_s, "steps_per_cpu_s": steps_per_cpu_s}


def _lumped_chain():
    """A numba loop of R rounds of the lumped kernel's dependent path, x += dt v, v = ((0.0 + a v) - g x) - g1 x
    - g2 x (six dependent floating-point operations, as x_{n+1} to v_{n+3/2} in reduced.transient._cd_lumped):
    the latency a step cannot beat."""
    import numba as nb

    @nb.njit
    def chain(x, v, dt, a, g, g1, g2, R):
        for _ in range(R):
            x += dt * v
            v = ((0.0 + a * v) - g * x) - g1 * x - g2 * x
        return x + v

    return chain


def lumped_rows(repeats: int) -> tuple[str, list[dict]]:
    """The lumped kernel (reduced.transient._cd_lumped, issue 28) against the register kernel it replaces on the
    discrete model (``explicit.LUMPED`` False), alternating in the same process on the 2 s discrete-impulse
    ringdown, and the latency of its dependent path per step (:func:`_lumped_chain`): (text for the headline row,
    detail rows)."""
    from reduced.transient import explicit

    system, x0, v0 = scene_model("discrete-impulse")
    runs, walls, cpus = {}, {True: [], False: []}, {True: [], False: []}
    load0 = os.getloadavg()[0]
    try:
        for flag in (True, False):
            explicit.LUMPED = flag
            integrate_explicit(system, x0, v0, LONG_S, FS)
        for _ in range(repeats):
            for flag in (True, False):
                explicit.LUMPED = flag
                c0, t0 = time.process_time(), time.perf_counter()
                runs[flag] = integrate_explicit(system, x0, v0, LONG_S, FS)
                walls[flag].append(time.perf_counter() - t0)
                cpus[flag].append(time.process_time() - c0)
    finally:
        explicit.LUMPED = True
    load1 = os.getloadavg()[0]
    same = all(np.array_equal(getattr(runs[True], k), getattr(runs[False], k)) for k in ("x", "v", "dissipated"))
    steps = runs[True].stats["n_steps"]
    chain = _lumped_chain()
    chain(0.0, 1.0, 1e-6, 0.99, 1e-3, 1e-4, 1e-4, 10)
    t = []
    R = 5_000_000
    for _ in range(5):
        c0 = time.process_time()
        chain(0.0, 1.0, 1e-6, 0.99, 1e-3, 1e-4, 1e-4, R)
        t.append(time.process_time() - c0)
    link = min(t) / R
    med = {f: float(np.median(walls[f])) for f in walls}
    cpu = {f: float(np.median(cpus[f])) for f in cpus}
    details = [{"scene": "discrete-impulse", "method": "explicit", "code": f"ours, {name} kernel", "median_s": med[f],
                "min_s": float(np.min(walls[f])), "max_s": float(np.max(walls[f])), "cpu_median_s": cpu[f],
                "repeats": repeats, "n_steps": steps, "energy_balance_error": runs[f].energy_balance_error}
               for f, name in ((True, "lumped"), (False, "register"))]
    details.append({"scene": "discrete-impulse", "method": "explicit", "code": "latency of the lumped kernel's "
                    "dependent path (6 floating-point operations) a step", "median_s": link})
    text = (f"the lumped kernel: {med[False] / med[True]:.2f}x the register kernel's wall time, "
            f"{cpu[False] / cpu[True]:.2f}x its CPU time (same process, alternating; "
            f"{'the same bits' if same else 'NOT the same bits'}); CPU time {steps / cpu[True]:.3g} steps/s, "
            f"a step {cpu[True] / steps * 1e9:.3g} ns = {cpu[True] / steps / link:.2g} x the latency of its dependent "
            f"path ({link * 1e9:.3g} ns measured); machine load (1 min) {load0:.1f} before, {load1:.1f} after")
    print(text, flush=True)
    return text, details


def block_roofline(form: dict, n: int, every: int, blocks_per_interval: float, steps_per_cpu_s: float,
                   peak: float) -> dict:
    """Where the block kernel sits (:mod:`reduced.transient._cd_block`): its flops and table bytes a step, from
    its tables' sizes (a check of the longest block's stop rows and a jump with the end-state rows,
    ``blocks_per_interval`` of each an output interval of ``every`` steps, a sample's two n x n products), against
    ``peak`` (flop/s, the one-core dgemm peak :func:`roofline` measures); and the block's two matrix-vector
    products timed alone on its own tables (warm, in L1): what a block cannot beat as written."""
    import numba as nb

    from reduced.transient import _cd_block

    TG, TS, RGL = form["TG"], form["TS"], form["RGL"]
    ns, RS, RG = TG.shape[2], TS.shape[3], int(RGL[0])
    mv = _cd_block._matvec

    @nb.njit
    def products(TGc, TSc, st, y, nxt, R):
        for _ in range(R):
            mv(TGc, st, y, RG, ns - 1)
            mv(TSc, st, nxt, RS, ns - 1)
            st[0] += 1e-300 * (y[0] + nxt[0])  # the next block starts from this one's end: a dependent chain
        return st[0]

    st = np.full(ns, 1e-6)
    st[-1] = 1.0
    y, nxt = np.empty(TG.shape[3]), np.empty(RS)
    TGc, TSc = np.ascontiguousarray(TG[0, 0]), np.ascontiguousarray(TS[0, 0])
    products(TGc, TSc, st, y, nxt, 10)
    t = []
    for _ in range(5):
        c0 = time.process_time()
        products(TGc, TSc, st, y, nxt, 100_000)
        t.append((time.process_time() - c0) / 100_000)
    pair = min(t)
    flops = (2.0 * ns * (RG + RS) * blocks_per_interval + 4.0 * n * n) / every
    bytes_ = 8.0 * ns * (RG + RS) * blocks_per_interval / every
    return {"flops_per_step": flops, "bytes_per_step": bytes_, "peak_flops_per_s": peak,
            "fraction_of_peak": flops * steps_per_cpu_s / peak, "table_bytes_per_s": bytes_ * steps_per_cpu_s,
            "products_s": pair, "block_s": every / (blocks_per_interval * steps_per_cpu_s),
            "rows_check": RG, "rows_jump": RS, "columns": ns}


def reduced_beam_explicit_rows(base: dict, repeats: int, commit: str) -> tuple[list[dict], list[dict]]:
    """The explicit rows of the 2 s rom-impulse ringdown of the 10-mode reduced beam, all from one loop
    (:func:`alternate`, CPU time): the default kernel (``coordinates="auto"``: the block kernel, issue 28) against
    the previous release's (``base``), the step-by-step kernel in the open-gap modal coordinates
    (``coordinates="modal"``, the block kernel's reference: no target) and the block kernel asked for by name
    (``coordinates="blocked"``: the default kernel again, a second measurement of it in the same loop) against
    today's physical-coordinate kernel; their differences over the first 0.2 s (round-off, not yet amplified by the
    chaotic motion). Headline rows: the default (target 3e7 steps/s in CPU time), the modal reference, the block
    kernel's own."""
    from reduced.transient import _cd_block

    system, x0, v0 = scene_model("rom-impulse")
    rate = RATES["rom-impulse"]
    fns = {c: partial(integrate_explicit, system, x0, v0, LONG_S, FS, step_basis="contact", coordinates=c)
           for c in ("auto", "physical", "modal", "blocked")}
    if "explicit" in base:
        fns["baseline"] = partial(base["explicit"].integrate_explicit, system, x0, v0, LONG_S, FS,
                                  step_basis="contact")
    load0 = os.getloadavg()[0]
    runs, t = alternate(fns, repeats)
    load1 = os.getloadavg()[0]
    ph, mo, bl, de, b_res = runs["physical"], runs["modal"], runs["blocked"], runs["auto"], runs.get("baseline")
    steps = mo.stats["n_steps"]
    cpu = {c: t[c]["median_s"] for c in t}
    details = [{"scene": "rom-impulse", "method": "explicit",
                "code": f"baseline {commit}" if c == "baseline" else f"ours, {c} coordinates", **t[c],
                "n_steps": steps, "energy_balance_error": runs[c].energy_balance_error} for c in t]
    loads = f"machine load (1 min) {load0:.1f} before, {load1:.1f} after, on {os.cpu_count()} cores"
    alt = f"median of {repeats}, alternating with the other explicit kernels of this scene"

    def against_physical(c: str) -> dict:
        """The row's time and its ratio to today's physical kernel (no target: a reference or a second look)."""
        return {"ours_s": cpu[c], "baseline": "explicit in physical coordinates, same process, alternating",
                "baseline_s": cpu["physical"], "ratio": cpu["physical"] / cpu[c], "target": "", "met": ""}

    def speeds(c: str) -> str:
        return (f"{steps / cpu[c]:.3g} steps/s in CPU time ({alt}; fastest run {steps / t[c]['min_s']:.3g}; wall "
                f"time {steps / t[c]['wall_median_s']:.3g})")

    rl = roofline(system.n, 3, 2, steps / cpu["modal"])
    form = next(iter(_cd_block._FORMS.values()))
    br = block_roofline(form, system.n, 25, 1.25, steps / cpu["auto"], rl["peak_flops_per_s"])
    details.append({"scene": "rom-impulse", "method": "explicit", "code": "roofline of the modal kernel", **rl})
    details.append({"scene": "rom-impulse", "method": "explicit", "code": "roofline of the block kernel", **br})
    same = all(np.array_equal(getattr(de, k), getattr(bl, k)) for k in ("x", "v", "dissipated"))
    default = {
        "what": f"explicit (central difference) ringdown, rom-impulse, {LONG_S:g} s: {steps} steps, {speeds('auto')}; "
                f"{loads}",
        "ours_s": cpu["auto"], "baseline": BASELINE.format(commit).replace("exact", "explicit") + ", alternating",
        "baseline_s": cpu["baseline"] if b_res is not None else "",
        "ratio": cpu["baseline"] / cpu["auto"] if b_res is not None else "",
        "error": (f"the default {de.stats.get('coordinates', '')} kernel: first {WINDOW_S:g} s differs from before "
                  f"by {head_diff(de, b_res, FS):.2g} of max |x| (round-off; the runs part later as the motion is "
                  f"chaotic); energy balance {de.energy_balance_error:.3g} (before: {b_res.energy_balance_error:.3g})"
                  if b_res is not None else "")
        + (f"; roofline (CPU time, same process): {br['flops_per_step']:.0f} flop and {br['bytes_per_step']:.0f} B "
           f"of tables a step (a check of {br['rows_check']} stop rows and a jump of {br['rows_jump']} end-state "
           f"rows, {br['columns']} columns, 1.25 of each an output interval of 25 steps, and a sample's two 12 x 12 "
           f"products), {br['fraction_of_peak']:.0%} of the measured {br['peak_flops_per_s']:.3g} flop/s one-core "
           f"dgemm peak, {br['table_bytes_per_s'] / 1e9:.3g} GB/s from L1/L2: neither bound; a block takes "
           f"{br['block_s'] * 1e9:.0f} ns, its two products alone (warm, chained block to block) "
           f"{br['products_s'] * 1e9:.0f} ns: the rest is the check of the rows against the contact state, the "
           f"energy and the sample"),
        "target": f">= {rate:.0e} steps/s in CPU time (<= {steps / rate:.3g} s)", "met": steps / cpu["auto"] >= rate}
    head = {"what": f"explicit (central difference) ringdown in the open-gap modal coordinates, rom-impulse, "
                    f"{LONG_S:g} s, step by step (the block kernel's reference, not the default): {steps} steps, "
                    f"{speeds('modal')}", **against_physical("modal"),
            "error": f"first {WINDOW_S:g} s differs from the physical kernel by {head_diff(mo, ph, FS):.2g} of max |x| "
                     f"(round-off; the runs part later as the motion is chaotic); energy balance "
                     f"{mo.energy_balance_error:.3g} (physical {ph.energy_balance_error:.3g}); {loads}; roofline (CPU "
                     f"time, same process): {rl['flops_per_step']} flop and {rl['bytes_per_step']} B (L1) a step, "
                     f"{rl['fraction_of_peak']:.0%} of the measured {rl['peak_flops_per_s']:.3g} flop/s one-core dgemm "
                     f"peak and {rl['l1_bytes_per_s'] / 1e9:.3g} GB/s from L1: neither bound; a step takes "
                     f"{rl['links_per_step']:.2g} x the latency of one dependent 12-term sum feeding a 12-term update "
                     f"({rl['link_latency_s'] * 1e9:.3g} ns measured), and its sums over the coordinates (tip rows, "
                     f"U^T y, the new velocity) each wait for the last: latency-bound"}
    blocked = {"what": f"explicit (central difference) ringdown in the open-gap modal coordinates, jumped in blocks "
                       f"of up to 25 steps while the contact state holds, rom-impulse, {LONG_S:g} s (the default "
                       f"kernel, asked for by name: a second measurement of the rom-impulse row's kernel in the same "
                       f"loop; that row carries the target): {steps} steps, {speeds('blocked')}",
               **against_physical("blocked"),
               "error": f"{'the same bits as the default run' if same else 'NOT the same bits as the default run'}; "
                        f"first {WINDOW_S:g} s differs from the step-by-step modal kernel by "
                        f"{head_diff(bl, mo, FS):.2g} and from the physical kernel by {head_diff(bl, ph, FS):.2g} of "
                        f"max |x| (round-off; the runs part later as the motion is chaotic); energy balance "
                        f"{bl.energy_balance_error:.3g} (physical {ph.energy_balance_error:.3g}); CPU time "
                        f"{cpu['modal'] / cpu['blocked']:.2f}x the modal kernel's; {loads}"}
    for row in (default, head, blocked):
        print(row, flush=True)
    return [default, head, blocked], details


def hammer_rows(base: dict, modes: list[int], repeats: int, commit: str) -> tuple[list[dict], list[dict]]:
    """Per output sample of the exact integrator on the hammer-test model (no gap closes)."""
    from bearingshaft.stages.hammer import default_location
    from reduced.models.loads import HalfSine
    from reduced.models.rig import virtual_rig
    from reduced.models.rom import RomSpec

    heads, details = [], []
    for nm in modes:
        rom = RomSpec(layout="assembly", planar=False, n_modes=nm).reduced(progress=False)
        rig = virtual_rig(rom, default_location(rom), (0.0, 0.0, -1.0))
        n = rig.system.n
        loads = rig.loads(HalfSine(peak_N=HAMMER_BLOW_N, duration_s=1e-3, start_s=0.01))
        z = np.zeros(n)
        per = {}
        for code, fn in (("ours", integrate_exact), *((("baseline", base["exact"].integrate_exact),) if base else ())):
            walls = {}
            for T in HAMMER_S:
                res, t = timed(partial(fn, rig.system, z, z, T, FS, loads=loads), repeats)
                walls[T] = t
                details.append({"scene": f"hammer-test n_modes={nm}", "method": "exact", "code": code,
                                "duration_s": T, **t, "n_events": res.stats["n_events"],
                                "energy_balance_error": res.energy_balance_error, "n_dofs": n})
            n_extra = round((HAMMER_S[1] - HAMMER_S[0]) * FS)
            per[code] = (walls[HAMMER_S[1]]["median_s"] - walls[HAMMER_S[0]]["median_s"]) / n_extra
            per[code + "_total"] = walls[HAMMER_S[1]]["median_s"]
        K = n  # kept terms of a state: one of each conjugate pair
        A = np.random.default_rng(0).standard_normal((2 * n, K)) + 1j
        u = np.ones(K, complex)
        _, tm = timed(partial(_matvecs, A, u, 100), repeats)
        matvec = tm["median_s"] / 100
        details.append({"scene": f"hammer-test n_modes={nm}", "method": f"numpy {2 * n} x {K} complex matvec",
                        "code": "reference", **tm, "n_dofs": n})
        heads.append({"what": f"exact, hammer-test model (n_modes = {nm}, {n} coordinates), cost of one output sample "
                              f"(no impact; whole {HAMMER_S[1]:g} s record at {FS:g} Hz: ours {per['ours_total']:.3g} s"
                              + (f", before {per['baseline_total']:.3g} s)" if base else ")"),
                      "ours_s": per["ours"], "baseline": BASELINE.format(commit) if base else "",
                      "baseline_s": per.get("baseline", ""),
                      "ratio": per["baseline"] / per["ours"] if base else "",
                      "error": f"one numpy {2 * n} x {K} complex matvec: {matvec:.3g} s",
                      "target": "a dense matvec (<= 4 x that matvec: the state and the work are two products)",
                      "met": per["ours"] <= 4.0 * matvec})
        print(heads[-1], flush=True)
    return heads, details


def dop853_rows(repeats: int, long_window: bool) -> tuple[list[dict], list[dict], list[dict]]:
    """Exact against DOP853 restarted at every crossing, at equal error, on the 0.2 s and 2 s windows."""
    system, x0, v0 = scene_model("discrete-impulse")
    heads, details, scans = [], [], []
    windows = [(WINDOW_S, DOP_RTOLS_SHORT, "max-norm error of x against the exact run")]
    if long_window:
        windows.append((LONG_S, DOP_RTOLS_LONG, "energy-balance error of the run"))
    for T, rtols, measure in windows:
        ref, t_ex = timed(lambda T=T: integrate_exact(system, x0, v0, T, FS), repeats)
        _, t_cold = timed(cold(lambda T=T: integrate_exact(system, x0, v0, T, FS)), repeats)
        ex_err = ref.energy_balance_error if T == LONG_S else 0.0
        details.append({"scene": "discrete-impulse", "method": "exact", "code": "ours", "duration_s": T, **t_ex,
                        "n_events": ref.stats["n_events"], "energy_balance_error": ref.energy_balance_error})
        details.append({"scene": "discrete-impulse", "method": "exact, tables worked out in the run", "code": "ours",
                        "duration_s": T, **t_cold, "n_events": ref.stats["n_events"],
                        "energy_balance_error": ref.energy_balance_error})
        runs = {}
        for rtol in rtols:
            c0, t0 = time.process_time(), time.perf_counter()
            res = integrate_dop853(system, x0, v0, T, FS, rtol=rtol, events=True)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            err = res.energy_balance_error if T == LONG_S else relative_error(res.x, ref.x)
            runs[rtol] = {"walls": [wall], "cpus": [cpu], "error": err}
            scans.append({"window_s": T, "rtol": rtol, "wall_s": wall, "cpu_s": cpu, "error": err,
                          "error_measure": measure, "energy_balance_error": res.energy_balance_error,
                          "n_events": res.stats["n_events"], "exact_n_events": ref.stats["n_events"],
                          "n_steps": res.stats["n_steps"]})
            print(scans[-1], flush=True)
        for target in ERROR_TARGETS:
            ok = [r for r in rtols if runs[r]["error"] <= target]
            if not ok:
                heads.append({"what": f"exact vs DOP853 restarted at every crossing, discrete-impulse {T:g} s, "
                                      f"error {target:g} ({measure})", "ours_s": t_ex["median_s"],
                              "baseline": "DOP853 restarted at every crossing: no rtol tried reaches it",
                              "baseline_s": "", "ratio": "", "error": "", "target": f">= {TARGET_RATIO:g}x",
                              "met": False})
                continue
            rtol = max(ok)  # the loosest (fastest) rtol that reaches the error
            run = runs[rtol]
            while len(run["walls"]) < repeats:  # the median of repeats at the chosen rtol
                c0, t0 = time.process_time(), time.perf_counter()
                integrate_dop853(system, x0, v0, T, FS, rtol=rtol, events=True)
                run["walls"].append(time.perf_counter() - t0)
                run["cpus"].append(time.process_time() - c0)
            t_dop = float(np.median(run["walls"]))
            details.append({"scene": "discrete-impulse", "method": f"dop853 events rtol {rtol:g}", "code": "reference",
                            "duration_s": T, "median_s": t_dop, "min_s": min(run["walls"]), "max_s": max(run["walls"]),
                            "cpu_median_s": float(np.median(run["cpus"])), "repeats": len(run["walls"]),
                            "energy_balance_error": ""})
            heads.append({"what": f"exact vs DOP853 restarted at every crossing, discrete-impulse {T:g} s, error <= "
                                  f"{target:g} ({measure}); exact with its tables kept from the warm-up run (with "
                                  f"the tables worked out in the run: {t_cold['median_s']:.3g} s, "
                                  f"{t_dop / t_cold['median_s']:.0f}x)",
                          "ours_s": t_ex["median_s"],
                          "baseline": f"integrate_dop853(events=True) at rtol {rtol:g}, same process",
                          "baseline_s": t_dop, "ratio": t_dop / t_ex["median_s"],
                          "error": f"DOP853 {run['error']:.2g}; exact "
                                   + (f"{ex_err:.2g}" if T == LONG_S else "the reference (round-off, ~1e-11)"),
                          "target": f">= {TARGET_RATIO:g}x", "met": t_dop / t_ex["median_s"] >= TARGET_RATIO})
            print(heads[-1], flush=True)
    return heads, details, scans


def short_label(what: str) -> str:
    """A bar label from a headline row's ``what``."""
    if "hammer-test" in what:
        n = what.split("n_modes = ")[1].split(",")[0]
        return f"exact, hammer-test n_modes = {n}\n(one output sample)"
    method = "exact" if what.startswith("exact") else "explicit"
    scene = "discrete-impulse" if "discrete-impulse" in what else "rom-impulse"
    if "jumped in blocks" in what:  # its grey bar is today's physical kernel, not the old release
        return f"explicit in blocks of steps, {scene}\n2 s ringdown (grey: the physical kernel)"
    if "open-gap modal coordinates" in what:  # its grey bar is today's physical kernel, not the old release
        return f"explicit in modal coordinates, {scene}\n2 s ringdown (grey: the physical kernel)"
    return f"{method}, {scene}\n2 s ringdown"


def baseline_name(heads: list[dict]) -> str:
    """The baseline of the bars as a user reads it: the previous release's kernels, at the commit the
    headline rows name.

    >>> baseline_name([{"baseline": "exact before issue 14 (fc521a5), same process"}])
    "the previous release's kernels (commit fc521a5), same process"
    >>> baseline_name([])
    "the previous release's kernels, same process"
    """
    commits = {m.group(1) for h in heads for m in [re.search(r"\(([0-9a-f]{7,40})\)", h.get("baseline") or "")] if m}
    at = f" (commit {', '.join(sorted(commits))})" if commits else ""
    return f"the previous release's kernels{at}, same process"


def figure(heads: list[dict], scans: list[dict], path: Path) -> None:
    """integrator_speed.png: :func:`draw` saved."""
    import matplotlib.pyplot as plt

    fig = draw(heads, scans)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def draw(heads: list[dict], scans: list[dict]):
    """Bars: each timing now and with the previous release's kernels; curves: DOP853's error against
    its time, the exact run's time (and error) marked. Legends sit below the axes, off the data."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def num(v):
        try:
            return float(v)
        except (TypeError, ValueError):
            return None

    fig, axes = plt.subplots(1, 2, figsize=(14, 6), constrained_layout=True)
    ax = axes[0]
    rows = [h for h in heads if num(h["baseline_s"]) is not None and "DOP853" not in h["what"]]
    y = np.arange(len(rows))
    ax.barh(y - 0.2, [num(h["baseline_s"]) for h in rows], 0.4, label=baseline_name(rows), color="0.6")
    ax.barh(y + 0.2, [num(h["ours_s"]) for h in rows], 0.4, label="this code", color="C0")
    for i, h in enumerate(rows):
        ax.text(num(h["ours_s"]), i + 0.2, f" {num(h['ratio']):.3g}x faster", va="center", fontsize=8)
    ax.set_yticks(y, [short_label(h["what"]) for h in rows], fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("time [s], median of the repeats in the median process (wall; CPU for the explicit rows, "
                  "alternating)")
    ax.set_title("The integrators now and with the previous release's kernels", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1, frameon=False)
    ax = axes[1]
    for T, marker, color in ((WINDOW_S, "o", "C0"), (LONG_S, "s", "C1")):
        pts = [s for s in scans if num(s["window_s"]) == T]
        if pts:
            ax.loglog([num(s["wall_s"]) for s in pts], [num(s["error"]) for s in pts], marker=marker, color=color,
                      label=f"DOP853 restarted at crossings, {T:g} s ({pts[0]['error_measure']})")
            for s in pts:
                ax.annotate(f"rtol {num(s['rtol']):.0e}", (num(s["wall_s"]), num(s["error"])), fontsize=6,
                            xytext=(6, 0), textcoords="offset points", va="center")
        ex = [h for h in heads if "DOP853" in h["what"] and f"discrete-impulse {T:g} s" in h["what"]]
        if ex:
            t = num(ex[0]["ours_s"])
            err = 1e-11 if T == WINDOW_S else num(ex[0]["error"].split("exact ")[-1])
            ax.loglog([t], [err], marker=marker, color=color, mfc="none", ms=10, ls="none",
                      label=f"exact, {T:g} s" + (" (its own error: round-off, ~1e-11)" if T == WINDOW_S else ""))
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("relative error")
    ax.set_title("DOP853 restarted at every crossing and the exact integrator, discrete-impulse", fontsize=10)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1, frameon=False)
    return fig


def redraw(out: Path) -> None:
    """The figure again from the CSV files (``--figure-only``)."""
    figure(read_csv(out / "integrator_headline.csv"), read_csv(out / "integrator_dop853.csv"),
           out / "integrator_speed.png")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="runs a median is taken of (>= 3)")
    ap.add_argument("--baseline-commit", default="fc521a5",
                    help="the previous release's kernels (the code before issue 14)")
    ap.add_argument("--hammer-modes", type=int, nargs="*", default=[60, 120])
    ap.add_argument("--no-dop853-2s", action="store_true", help="skip the 2 s DOP853 window (minutes a run)")
    ap.add_argument("--processes", type=int, default=None,
                    help="child processes the whole measurement runs in, one after the other; each headline row is "
                         "that of the median process (benchmarks/process_median.py; odd; 1: this process alone; "
                         "default 5, with --explicit-only 1)")
    ap.add_argument("--out", default="results/performance")
    ap.add_argument("--figure-only", action="store_true", help="redraw integrator_speed.png from the CSV files")
    ap.add_argument("--explicit-only", action="store_true",
                    help="measure only the explicit rows (both scenes, the lumped kernel, the modal and block "
                         "kernels) and replace them in the tables; the exact and DOP853 rows are kept")
    args = ap.parse_args(argv)
    if args.repeats < 3:
        ap.error("--repeats must be >= 3")
    out = Path(args.out)
    if args.figure_only:
        redraw(out)
        return 0
    if args.processes is None:
        args.processes = 1 if args.explicit_only else 5
    if args.processes < 1 or args.processes % 2 == 0:
        ap.error("--processes must be odd and >= 1")
    if args.explicit_only and args.processes > 1:
        ap.error("--explicit-only replaces rows of one process's tables: use --processes 1 (or measure everything)")
    out.mkdir(parents=True, exist_ok=True)
    if args.processes > 1:
        return in_processes(out, args, argv if argv is not None else sys.argv[1:])
    info = machine_rows()
    info.append({"key": "probe_ms_start", "value": probe_ms()})
    if args.explicit_only:
        return explicit_only(out, args, info)
    base = load_baseline(args.baseline_commit)
    with single_thread_blas():
        heads, details, scans = run_all(base, args)
    info.append({"key": "load_1min_end", "value": os.getloadavg()[0]})
    info.append({"key": "probe_ms_end", "value": probe_ms()})
    fields = ["what", "ours_s", "baseline", "baseline_s", "ratio", "error", "target", "met"]
    write_rows(out / "integrator_headline.csv", [{k: (f"{v:.4g}" if isinstance(v, float) else v)
                                                  for k, v in r.items()} for r in heads], fields)
    dfields = sorted({k for r in details for k in r}, key=lambda k: (k not in ("scene", "method", "code"), k))
    write_rows(out / "integrator_details.csv", details, dfields, float_format=".5g")
    write_rows(out / "integrator_dop853.csv", scans, float_format=".5g")
    write_rows(out / "integrator_machine.csv", info)
    figure(heads, scans, out / "integrator_speed.png")
    print(f"wrote {out}/integrator_{{headline,details,dop853,machine}}.csv and integrator_speed.png")
    return 0


def in_processes(out: Path, args, argv: list[str]) -> int:
    """The whole measurement in ``args.processes`` child processes (:func:`process_median.children`, in a
    temporary folder), then the tables of ``out`` from them: each headline row that of the median
    process (:func:`process_median.median_rows`, a ``processes`` column with every process's number and speed
    probe); integrator_processes.csv the per-process rows; integrator_details.csv every process's details (a
    ``process`` column); integrator_dop853.csv the scans of the process chosen for the 0.2 s DOP853 row at the
    loosest error (marked ``chosen`` in integrator_processes.csv; every process's in
    integrator_dop853_processes.csv); integrator_machine.csv this process's
    machine rows and each child's probe and load."""
    with children(str(Path(__file__).resolve()), argv, args.processes) as dirs:
        merge_children(dirs, out)
    print(f"wrote {out}/integrator_{{headline,processes,details,dop853,machine}}.csv and integrator_speed.png "
          f"from {args.processes} processes")
    return 0


def merge_children(dirs: list[Path], out: Path) -> None:
    """The tables and figure of ``out`` from the children's folders ``dirs`` (:func:`in_processes`).

    Parameters
    ----------
    dirs : list of Path
        Each child's folder of integrator_*.csv.
    out : Path
        The folder written.

    Returns
    -------
    None
    """
    chosen = merge(dirs, "integrator", out, concat=("integrator_details.csv",))
    dop = [i for i, h in enumerate(read_csv(dirs[0] / "integrator_headline.csv")) if "DOP853" in h["what"]]
    k_fig = chosen[dop[0]] if dop else 0  # integrator_processes.csv marks it chosen
    write_rows(out / "integrator_dop853_processes.csv",
               [{"process": k, **r} for k, d in enumerate(dirs) for r in read_csv(d / "integrator_dop853.csv")])
    write_rows(out / "integrator_dop853.csv", read_csv(dirs[k_fig] / "integrator_dop853.csv"))
    redraw(out)


def explicit_only(out: Path, args, info: list[dict]) -> int:
    """Measure the explicit rows alone (:func:`exact_rows` for the explicit method, :func:`lumped_rows`,
    :func:`reduced_beam_explicit_rows`) and put them in place of the explicit rows of ``out``'s tables, in the same
    order; the exact and DOP853 rows stay as measured before. The machine file gets this run's keys prefixed
    ``explicit_``; the figure is redrawn."""
    base = load_baseline(args.baseline_commit)
    base = {"explicit": base["explicit"]} if "explicit" in base else {}
    with single_thread_blas():
        heads, details = ringdown_rows(base, args, methods=("explicit",))
    info.append({"key": "load_1min_end", "value": os.getloadavg()[0]})
    info.append({"key": "probe_ms_end", "value": probe_ms()})
    fmt = {r["what"].split(",")[0] + r["what"].split(",")[1]: {k: (f"{v:.4g}" if isinstance(v, float) else v)
                                                                for k, v in r.items()} for r in heads}
    tag = "explicit (central difference) ringdown"
    old = read_csv(out / "integrator_headline.csv")
    rows, left = [], dict(fmt)
    for r in old:
        key = r["what"].split(",")[0] + r["what"].split(",")[1]
        if r["what"].startswith(tag):
            if key in left:
                rows.append(left.pop(key))
        else:
            rows.append(r)
    rows += list(left.values())
    fields = ["what", "ours_s", "baseline", "baseline_s", "ratio", "error", "target", "met"]
    write_rows(out / "integrator_headline.csv", rows, fields)
    old_d = [r for r in read_csv(out / "integrator_details.csv") if r.get("method") != "explicit"]
    dfields = list(old_d[0]) if old_d else []
    dfields += sorted({k for r in details for k in r} - set(dfields))
    write_rows(out / "integrator_details.csv", old_d + [{k: r.get(k, "") for k in dfields} for r in details], dfields,
               float_format=".5g")
    m_old = [r for r in read_csv(out / "integrator_machine.csv") if not r["key"].startswith("explicit_")]
    write_rows(out / "integrator_machine.csv", m_old + [{"key": f"explicit_{r['key']}", "value": r["value"]}
                                                        for r in info])
    redraw(out)
    print(f"updated {out}/integrator_{{headline,details,machine}}.csv and integrator_speed.png")
    return 0


def ringdown_rows(base: dict, args, methods=("exact", "explicit")) -> tuple[list[dict], list[dict]]:
    """The ringdown rows (:func:`exact_rows` for ``methods``), the lumped kernel's comparison put
    into the 3-DOF explicit row's error column, and the reduced beam's explicit rows: (headline rows, details).

    Parameters
    ----------
    base : dict
        The previous release's kernels (:func:`load_baseline`).
    args : argparse.Namespace
        ``repeats`` and ``baseline_commit``.
    methods : tuple of str
        The methods of :func:`exact_rows`.

    Returns
    -------
    tuple of (list of dict, list of dict)
    """
    heads, details = exact_rows(base, args.repeats, args.baseline_commit, methods)
    text, d = lumped_rows(args.repeats)
    details += d
    for h in heads:
        if h["what"].startswith("explicit (central difference) ringdown, discrete-impulse"):
            h["error"] = f"{h['error']}; {text}"
    h, d = reduced_beam_explicit_rows(base, args.repeats, args.baseline_commit)
    return heads + h, details + d


def run_all(base: dict, args) -> tuple[list[dict], list[dict], list[dict]]:
    heads, details = ringdown_rows(base, args)
    h, d = hammer_rows(base, args.hammer_modes, args.repeats, args.baseline_commit)
    heads += h
    details += d
    h, d, scans = dop853_rows(3, not args.no_dop853_2s)
    return heads + h, details + d, scans


if __name__ == "__main__":
    raise SystemExit(main())
