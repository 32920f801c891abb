"""One performance table: the headline rows of every speed benchmark, in results/performance/.

    python benchmarks/performance_summary.py [--folder results/performance]

Reads the headline tables the benchmarks write (columns what, ours_s, baseline, baseline_s,
ratio = baseline_s / ours_s, error, target, met) and their machine files, and writes

- ``summary.csv``: every headline row, with the benchmark that measured it and the command that
  regenerates it;
- ``README.md``: the same table in words, which baseline each ratio uses, the machine and library
  versions of each measurement, and the targets not met.

It measures nothing itself: run the benchmarks first (their commands are in SOURCES). A headline
file that is missing is named in README.md as not measured, never silently left out.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bearingshaft.output import write_rows  # noqa: E402

# (headline file, machine file, what it measures, command, what a bare number in its error column is)
SOURCES = (
    ("integrator_headline.csv", "integrator_machine.csv", "ringdown integrators",
     "PYTHONPATH=. python benchmarks/integrator_speed.py --repeats 5 --processes 5", ""),
    ("modal_headline.csv", "modal_machine.csv", "FE modal analysis, 112,629 DOFs",
     "python benchmarks/modal_speed.py --sizes 0.012 --repeats 3",
     "largest relative residual ||K phi - w^2 M phi|| / ||K phi|| over the 16 modes (a soft-spring mode; "
     "per mode with its round-off floor in modal_residuals.csv)"),
    ("modal_scaling_headline.csv", "modal_scaling_machine.csv", "FE modal analysis, scaling with DOFs",
     "python benchmarks/modal_scaling.py --headroom 0.9",
     "largest residual over its round-off floor, over all sizes and modes"),
    ("fep_headline.csv", "fep_machine.csv", "frequency-energy study (NNMs by HB and shooting)",
     "python benchmarks/fep_speed.py --repeats 3", ""),
    ("converged_curve_headline.csv", "converged_curve_machine.csv",
     "converged main curve with stability per level (issue 25)",
     "PYTHONPATH=. python benchmarks/converged_curve_speed.py --repeats 2 --processes 5", ""),
    ("job_headline.csv", "job_machine.csv", "the main job and the test suite, whole",
     "PYTHONPATH=. python benchmarks/job_times.py --no-baseline --runs 3", ""),
)
# what a reader must know beside the table
SPEED_STATES = (
    "this machine's cores run in two speed states, switching within a second, each core on its own "
    "(machine_speed.png, `PYTHONPATH=. python benchmarks/machine_speed.py --seconds 90`, 2026-11-27 18:01-18:03 UTC): "
    "a compiled loop of sin and exp calls takes ~4.5 ms or ~7 ms, the fast state 30 % of the time, while a "
    "dependent multiply-add chain shows no such states (2.5-3.3 ms). Nothing else ran in this guest and it had "
    "no steal time: the slow state comes from the host. Store- and call-heavy code such as the exact "
    "integrator's kernels runs 1.5-1.7x slower in it (the 2 s exact ringdown 18-22 ms against 31-36 ms)"
)
CAVEATS = [
    "The ringdown integrator rows and the converged-curve rows are each the row of the median of five processes "
    "(benchmarks/process_median.py; the per-process numbers and each process's speed probe are in the headline "
    "file's `processes` column and in integrator_processes.csv, converged_curve_processes.csv), because "
    + SPEED_STATES + ". A row timed in one process draws one state: session 14's table (the exact ringdown 20.75 "
    "ms, 1240x on the 0.2 s window at 1e-6) and session 15's single-process converged curve (9.7 s) were fast "
    "draws. The five-process integrator run: 2026-11-27 17:14-17:46 UTC, load 0.7-1.1, the kernels of 7f87532; "
    "the converged curve: 17:50-17:58 UTC.",
    "The main job and the suite are each the run of the median wall time of three, one after the other "
    "(`job_times.py --runs 3`, 2026-11-27 20:11-20:47 UTC), each run watched by `machine_speed.py --watch` (a "
    "short probe on each core every 2 s): a run of several minutes averages the states, but how much of the time "
    "the host holds our cores in the fast one changes by the hour (36-54 % of these runs). On the same code the "
    "job took 322-353 s and the suite 223 s at 15:59-16:37 UTC (session 15, met), 374-449 s and 244-307 s since.",
]

# what limits each target not met, from the profiles (a row matches by the start of its ``what``)
LIMITS = (
    ("explicit (central difference) ringdown, discrete-impulse",
     "the step is the lumped kernel since session 13 (reduced.transient._cd_lumped, issue 28: diagonal M and C and "
     "each stop on one coordinate, so the register kernel's zero terms are left out, the stops' thresholds sit in "
     "registers and the first row's 0.0 + leaves the path from x to v; the same bits, "
     "tests/test_explicit_lumped_kernel.py), 1.7x the register kernel's CPU time in the same process "
     "(alternating, the row's accuracy column: 1.7-2.0x in five runs at load 2-10). The row was measured at load "
     "2.0 (10:08 UTC, another session's job on both cores): 5.25e7 steps/s; under load 8-10 the wall times were "
     "2.5-4x the CPU times (5.5-6.6e7 steps/s in CPU time). A step is ~2.2x the latency of its dependent path "
     "x_{n+1} -> v_{n+3/2} -> x_{n+2} (six dependent floating-point "
     "operations, ~8 ns measured) and issues ~55 floating-point operations; each step needs the last one's "
     "result, so steps cannot overlap, and the results are kept bit for bit"),
    ("explicit (central difference) ringdown, rom-impulse",
     "the default kernel is the block kernel (reduced.transient._cd_block): while the contact state holds it jumps "
     "up to 25 steps with two matrix-vector products from the block's start state (the stop rows of its steps, "
     "56 x 25, and the end state, 40 x 25), 1.25 of each an output interval on this run (it changes contact state "
     "~10,000 times). Session 14 (issue 28): the end-state table also gives the stop rows at the block's end and "
     "at the next step, so a block's energy needs no sums over the coordinates and the next block's contact state "
     "is read off them; the check counts the rows outside the state's bounds (an integer sum the compiler "
     "vectorises); what the blocks carry goes from call to call in a per-run array; a run's max |x| without a "
     "|x| array of the record: 1.19-1.32x the CPU time of the session's start in the same process (alternating, "
     "load 7-10; x and v the same bits, the work within 1e-14). This row: a full run on the quiet machine after "
     "the session's merges (2026-11-27 13:53 UTC, load 1.2, sum(range(10**6)) 20 ms): 3.37e7 steps/s in CPU time "
     "(fastest run 3.75e7). Under load 6.5-7.6 (12:22 UTC, sum(range(10**6)) 57 ms) the same code gave 2.90e7 "
     "(fastest 3.13e7) and the same kernel asked for by name in the same loop 3.12e7: the two rows, now measured "
     "alike, differ by the load's noise (7 %; 20 % "
     "before, when one was measured back to back and the other a minute later alternating, medians of wall "
     "times; the kernel's CPU time was seen to jump between two levels ~1.6x apart in streaks of runs whatever "
     "their order, from other processes on the machine). On the quiet machine of 11:07 UTC the session's start "
     "measured 3.03e7. The roofline in "
     "the accuracy column: "
     "the block kernel uses under a fifth of the core's multiply-add peak and is not bandwidth-bound; about half a "
     "block is its two products (timed alone), the rest the check of the rows, the energy and the sample's two "
     "12 x 12 products; padding the tables to 16 rows, eight columns a pass, row tiles held in registers, the "
     "sample's products in 16-wide padded rows were each slower or no faster (measured, same process)"),
    ("exact vs DOP853 restarted at every crossing",
     "the machine's speed states (Caveats): the 0.2 s window at error 1e-6 gave 1248, 593, 588, 830 and 1517x in "
     "the five processes, met in two: ours took 2.4-2.8 ms in the two processes whose run drew the fast state and "
     "4.9-5.2 ms in the three that drew the slow one, DOP853 2.9-4.2 s in all five. At 1e-8 the same window "
     "gives 1124x (920-2257x), the 2 s window 1266x at 1e-6 and 1659x at 1e-8. The exact run's kernel (perf, "
     "issue 28) spends about a quarter of its time in libm (sincos, exp, expm1 of the terms e^{lam tau} at each "
     "march step) and most of the rest in the march's chains of dependent sqrt and divisions (the safe steps); "
     "no change that keeps the bits and pays was found (session 13; a change of the march moves the event "
     "times by round-off, hence every exact science file). Session 16 tried summing the work integral's "
     "matrix product without its scratch vector (the same bits): 1.01x, not kept"),
    ("exact ringdown, discrete-impulse",
     "the machine's speed states (Caveats): 36.0, 36.0, 34.5, 35.4 and 34.7 ms in the five processes, each "
     "started in the slow state (its probe 6.9-8.5 ms); a fast process runs it in 18-22 ms (session 14's 20.75 "
     "ms). Of a 2 s run (fast state), 15 ms are its 12,562 events (~1.2 us an event: the march's terms and "
     "safe steps, the segment's start and end) and ~10 ms its 40,000 output samples, 4 ms of them the "
     "dissipated work of each sample; in alternating same-process runs the free kernel is 1.6x the one before "
     "issue 28"),
    ("exact, hammer-test model",
     "the machine's load (integrator_machine.csv: 10-16 on 2 cores during the issue-28 runs; this row was met "
     "at load ~1 with the same per-sample code)"),
    ("FE modal, 112,629 DOFs, 16 modes: mesh",
     "measured on a quiet machine (2026-11-27 05:05 UTC, load 1.0-1.1): 8.9x in wall time (11.6 s against 103 s), "
     "9.0x in CPU (11.9 s against 107 s); 2026-11-26 22:11 UTC (load 0.5-1.1): 9.0x wall, 9.4x CPU. Of ours, in CPU "
     "on one thread: PARDISO's analysis and factorization 0.65-0.75 + 4.0-4.9 s (about 108 GFLOP at 25 GFLOP/s), 68 "
     "solves in 10 block calls 2.3-2.5 s (16, 16, 10, then 4 x 6, then 2 right-hand sides; 0.094 s for 1 column, 0.35 "
     "s for 16), sparse products ~1.5 s, dense work ~1.2 s, assembly 0.8-1.0 s. The twelve modes below 34 Hz converge "
     "by step 3; the four at 703-998 Hz gain only 20-50x a step, which forces the 10 steps. Tried and not faster "
     "(2026-11-26/27): orderings 0/2/3, VBSR settings, RCM or random input orderings, two-level factorizations (the "
     "improved one fails); single-precision factorization (PARDISO stops: K - sigma M's condition number ~1e10 is "
     "beyond float32); more guard vectors (8 steps but 124-180 solves), a larger start block (10 steps), topping up "
     "late blocks (9 steps, 90-144 solves), one Gram-Schmidt pass (fails the orthogonality check), PARDISO solves on "
     "2 threads (other bits), MKL's code paths (its generic kernels load on this AMD EPYC; its dgemm 35-44 GFLOP/s "
     "against OpenBLAS's 46), factorizing beam and tube apart (77.1M against 80.0M factor entries: no gain). Kept: "
     "the factorization beside the Krylov start (same bits, 0.3 s wall), the springs' and tip masses' entries merged "
     "into K and M by a numba CSR merge (same bits, 0.2-0.5 s CPU), has_pardiso without importing pypardiso (0.5-0.9 "
     "s CPU a process). Session 12 (2026-11-27, load 7-12 on a host reporting GenuineIntel family 6 model 207, where "
     "MKL loads its AVX-512 kernels): kept the blocks' fragment with OCC's full glue (the same mesh bit for bit, "
     "build_mesh 1.34 -> 1.00 CPU s) and a row-parallel numba product from 6 columns (the same bits; 24 columns "
     "0.149 -> 0.106 CPU s). Measured and dropped: a start block near the modes (the converged modes plus a relative "
     "error 1e-1, 1e-2, 1e-3, standing in for a coarse-mesh solution: 8, 8, 7 steps and 57, 55, 50 solves against "
     "10 and 66-68) saves at most 2-3 of the slow steps, while any other start block moves the soft-spring modes' "
     "frequencies by up to 3e-4 (their residual floor is ~1e-3 relative), so agreement to 1e-9 cannot be had; a "
     "Chebyshev filter before the first solve needs ~1e4 products with K (lambda_max ~4e13 rad^2/s^2, 1 MHz, "
     "against the 1368 Hz seventeenth mode) where one block solve does it; a better shift: with a Cholesky factor "
     "the shift stays below the first mode, and the slow modes' rate is fixed by (998 / 1368)^2 = 0.53 whatever it is"),
    ("converged main curve with stability, discrete-frc 10 N",
     "the machine's speed states (Caveats): 11.92, 15.25, 15.46, 9.81 and 11.93 s CPU in the five processes "
     "(medians of 2), met in one, whose probe was in the fast state at its start and end (4.6/4.8 ms); the stage's "
     "path 19.0 s in the median process. Session 15's single run, 9.7 s (9.6, 9.8), was most likely a fast "
     "draw (no probe was recorded then). "
     "Session 14: the curve is timed from the "
     "linear orbit at the band's top (bearingshaft.stages.frc.linear_start_families: no HB at all; the same family, "
     "its extent, 36 folds and stability, tests/test_exact_frc_robust.py; 5185 points, 17.13-900 Hz), 1.4-1.6x less "
     "CPU than the stage's path in the same process; and a point costs less, bit for bit the same family (Y, "
     "multipliers, peaks, test signs, folds; discrete-frc 1 N and 10 N, rom-frc 1 N and 10 N): the fold, pitchfork "
     "and period-doubling test signs by elimination (sign of det(A -+ I) per symmetry block, a small numba kernel) "
     "instead of four eigenvalue problems a point, and the peaks skip the contact-state stretches bounded inside the "
     "extremes already found: 1.29x CPU on the discrete 10 N family (median of 4, old and new code alternating in "
     "one process, load 8), 1.1x at 1 N, none on rom-frc 10 N (0.97x, one pair). What limits it: the path's length "
     "(1176 changes of the contact events; 5185 points) times 2.5-3 ms a point: ~5 marches of the 8-node flow a "
     "point (3-4 Newton iterations of the corrector at tol 1e-8: a first step of ~1e-4 contracts only ~0.3, and "
     "stopping on a contraction estimate would save ~9 % of the marches but leave the orbits 1e-8 from exact "
     "instead of round-off), the refused steps at grazings (2838 marches for 1896 refusals), the Jacobians and "
     "their LU, the peaks, and Python between them"),
    ("main job, bearingshaft run",
     "the machine's speed states (Caveats): on the same code the job took 322, 348 and 353 s wall (634-696 s CPU) "
     "at 2026-11-27 15:59-16:37 UTC (session 15, met), 377, 412, 449 and 420 s (745-886 s CPU) at 18:12-18:46 "
     "(session 16) and 426, 412 and 374 s (838, 810 and 738 s CPU) at 20:11-20:32 with the cores in their fast "
     "state 36, 42 and 54 % of each run (session 17, the row, `job_times.py --what job suite --no-baseline --runs "
     "3`): met in 3 of 10 runs. The CPU time falls with the fast share, about 1040 - 560 f s through these three "
     "runs (three points: a trend, not a law), so 360 s wall (~710 s CPU) needs the cores fast ~60 % of the time "
     "or more. The job is CPU-bound on 2 cores (the stages' walls sum to ~2x the job's): rom-frc (200 s CPU alone, "
     "its 10 N response map 47-65 s of it, in _periods_kernel, the exact period map and its tangent, and its 10 N "
     "and 1 N converged curves 38-49 and 31 s, the forced shooting's march, Jacobian, peaks and LU), discrete-frc "
     "(123 s alone) and discrete-friction-frc (~70-85 s) are most of it, so meeting 360 s in the slow state needs "
     "about a fifth less work, spread over kernels with no single hot spot left (session 17: cProfile of each "
     "part of the stage in one process). Session 15 cut, with every "
     "science file byte-identical: the march's |z| inlined (glibc's hypot to the bit), _Retrace's partial-sum "
     "prefilter and a cap on a switch's wandering Newton steps (rom-frc 1 N families 1.19x), Hill's method split "
     "by harmonic parity on half-wave symmetric orbits (rom-frc point checks 15.3 -> 6.4 s CPU), the stops' "
     "moments in one kernel, friction slider states kept per point and the NNM Jacobian summed on its nonzero "
     "blocks; reduced/_kernel_cache.py clears numba's caches when any source of the package changes (numba "
     "stamps a kernel's cache with its own file only)"),
    ("test suite, python -m pytest",
     "the machine's speed states (Caveats): on the same code the suite took 223 s wall, 433 s CPU at 16:13 UTC "
     "(session 15, met), 244-307 s in nine runs at 18:05-19:30 (session 16) and 278, 275, 265, 247 and 275 s "
     "(478-536 s CPU) at 19:46-20:47 (session 17; the last three the row, with the cores fast 44-48 % of each; "
     "the first and third failed one test, on a display bug fixed since: digits.human wrote 1010 MiB as "
     "1.01e+03 MiB): met in 1 of 17 runs. Meeting 240 s in the slow state needs about a seventh less work. The "
     "suite is CPU-bound on its 2 xdist workers (the tests' own durations sum to 519 s of 549 worker-seconds), "
     "the heaviest files test_results_folder (forked CLI runs), test_modal_speed_paths and test_hammer, and no "
     "test above 19 s. "
     "Session 15 made collection lighter (the import graph and docstring checks parse the packages on first "
     "use; the suite writes bytecode although this machine's environment sets PYTHONDONTWRITEBYTECODE), took "
     "three fixtures' reduced models from the model cache and solved the Timoshenko reference by shift-invert "
     "Lanczos"),
    ("hammer-test record with friction (mu = 0.3, axial + lateral), 200 N blow, cold",
     "session 14 passes through the states entered just after a closing whose slots fall at once (zero starts) and "
     "reaches omega_max tau = 1: states built 23/34/40 -> 15/24/26 after the 200/500/1000 N records; cold ratios "
     "1.29/1.44/1.25 (this row, 2026-11-27 13:49 UTC, quiet) and 1.67/1.71/1.76 (13:20, the same probe on its "
     "branch, quiet), against 1.86/1.98/1.80 for session 13's probe at 13:17 in the same series. Before: the 200 N "
     "record's cold ratio straddled 2: 2.06, then 1.64 and 2.18 "
     "in two quiet runs (2026-11-27 10:54 and 10:57 UTC; 500 N 1.73, 1.80; 1000 N 1.96, 1.59). Of the 23 friction "
     "states the 200 N record builds (a 260 x 260 eigendecomposition and inverse each, 40-80 ms), 16-21 a record are "
     "entered at an event where a slot or a slider's cone starts at zero and are not passed through "
     "(reduced.transient.friction_probe declines them: the kernel's own rules decide there); the friction model's "
     "top mode (22.97 kHz against 15.57 kHz) also makes the anti-alias rate 3x instead of 2x"),
    ("FE modal, 112,629 DOFs: relative residual",
     "the twelve soft-spring modes (0.4-34 Hz) stop at 1-3x their round-off floor eps |||K| |phi||| / ||K phi||, "
     "above 1e-8 in double precision; the elastic modes reach 4-8e-10"),
    ("FE modal scaling",
     "the in-core sparse Cholesky factor: 1,176,039 DOFs need an estimated 23.4 GiB (factor 13.4 GiB), "
     "refused before meshing; PARDISO's out-of-core mode is untried"),
    ("bearingshaft nnm --scene discrete-fep, wall",
     "profile: HB continuation ~22 s (45,000 residual evaluations: numpy call overhead at H <= 15, an O(N H) "
     "synthesis and a 306x306 LU at H = 50), shooting ~9 s (95 % of its flows are spent in guesses that fail "
     "after 25 Gauss-Newton iterations; giving up earlier loses 2 of NNM 1's 51 orbits), Hill's QZ on 186x186 "
     "pencils ~5 s, the DOP853 check of the NNM 2 relation ~3.5 s, imports and plots ~5 s"),
)
# the same benchmarks at the same code on an earlier machine of the same kind (2026-11-23; /proc/cpuinfo
# also said AMD EPYC, 2 cores): what moves with the machine, for a reader comparing runs
EARLIER_MACHINE = (
    "discrete-fep 52.4 s against 116.5 s before issue 14 (2.23x)",
    "FE modal at 112,629 DOFs 19.4 s against 126 s (6.5x)",
    "explicit steps 3.93e7 /s (3-DOF) and 9.47e6 /s (reduced beam)",
    "exact against DOP853 restarted at every crossing: 764x and 1370x on the 0.2 s window, 896x and 1200x on "
    "the 2 s window (errors 1e-6 and 1e-8), the exact run 4.9 and 27.6 ms, DOP853 3.8-33 s",
    "and on this machine, one run earlier in the same session (2026-11-26 15:10 UTC, three helper agents "
    "starting beside it): the exact 0.2 s run took 3.6 ms instead of 2.0 ms and DOP853 7 % longer, so 654x "
    "and 1131x on the 0.2 s window, 990x and 1353x on the 2 s window: the 1e-6 rows, met by 6 % and 1 % on a "
    "quiet machine, are missed with a little load",
)
COLUMNS = ("what", "ours_s", "baseline", "baseline_s", "ratio", "error", "target", "met")


# -- headline rows of the benchmarks that write only their own tables (issues 25 and 27) ----------------------
def _short(what: str, n: int = 110) -> str:
    """A row's ``what`` cut at a word boundary to at most n characters (and an ellipsis)."""
    return what if len(what) <= n else what[:n].rsplit(" ", 1)[0] + " ..."


def _median(values: list[float]) -> float:
    v = sorted(values)
    return 0.5 * (v[(len(v) - 1) // 2] + v[len(v) // 2])


def _response_map_rows(results: Path) -> list[dict]:
    """The response map of the highest level (both directions, regimes and exponents): median wall and CPU of
    the serial runs, target 60 s (issue 25)."""
    rows = [r for r in _read(results / "response-map-speed" / "response_map_speed_timing.csv") if r["way"] == "serial"]
    top = max(float(r["level"]) for r in rows)
    runs = [r for r in rows if float(r["level"]) == top]
    wall, cpu = _median([float(r["wall_s"]) for r in runs]), _median([float(r["cpu_s"]) for r in runs])
    n = int(runs[0]["frequencies_up"]) + int(runs[0]["frequencies_down"])
    return [{"what": f"response map of one level, discrete-frc {top:g} N: up and down, {n} frequencies "
                     f"({runs[0]['fine_step_hz']} Hz steps over {runs[0]['bands_hz']} Hz), regimes and Lyapunov "
                     f"exponents, one process; median of {len(runs)} runs (CPU {cpu:.3g} s)",
             "ours_s": f"{wall:.4g}", "baseline": "", "baseline_s": "", "ratio": "", "error": "",
             "target": "<= 60 s", "met": str(wall <= 60.0)}]


COLD = " (its friction tables built in the run)"


def _hammer_friction_rows(results: Path) -> list[dict]:
    """The hammer-test record with friction against the frictionless one, per level: cold (tables built in the
    run) and warm, target 2x (issue 27). CPU seconds (the benchmark's own ratios): the work, whatever the load of
    the shared machine; the wall seconds beside them in its table."""
    rows = _read(results / "hammer-friction-speed" / "hammer_friction_speed.csv")
    base = {r["level_N"]: r for r in rows if r["model"] == "frictionless"}
    out = []
    for r in (r for r in rows if r["model"] == "friction"):
        b = base[r["level_N"]]
        for how in ("cold", "warm"):
            ours, ref = float(r[f"{how}_cpu_s"]), float(b[f"{how}_cpu_s"])
            out.append({"what": f"hammer-test record with friction (mu = 0.3, axial + lateral), "
                                f"{float(r['level_N']):g} N blow, {how}" + COLD * (how == "cold") + ", CPU s",
                        "ours_s": f"{ours:.4g}", "baseline": f"the frictionless record, {how}, same process",
                        "baseline_s": f"{ref:.4g}", "ratio": f"{ours / ref:.3g}",
                        "error": f"energy balance {r['energy_balance_error']}", "target": "<= 2x the frictionless",
                        "met": str(ours / ref <= 2.0)})
    return out


def _friction_ringdown_rows(results: Path) -> list[dict]:
    """The discrete friction model's 2 s exact ringdown, target 0.1 s (issue 27)."""
    rows = _read(results / "friction-speed" / "friction_speed.csv")
    r = next(r for r in rows if r["case"] == "scene" and r["method"] == "exact" and float(r["mu"]) > 0)
    return [{"what": f"discrete friction model, 2 s exact ringdown (mu = {r['mu']}, {r['n_events']} events), median",
             "ours_s": r["median_s"], "baseline": "", "baseline_s": "", "ratio": "",
             "error": f"energy balance {r['energy_balance_error']}", "target": "<= 0.1 s",
             "met": str(float(r["median_s"]) <= 0.1)}]


# (benchmark folder under results/, what it measures, command, rows from its own tables)
OWN_TABLES = (
    ("response-map-speed", "response map (issue 25)",
     "PYTHONPATH=. python benchmarks/response_map_speed.py --levels 10", _response_map_rows),
    ("hammer-friction-speed", "hammer test with friction (issue 27)",
     "PYTHONPATH=. python benchmarks/hammer_friction_speed.py", _hammer_friction_rows),
    ("friction-speed", "friction ringdown (issue 27)",
     "PYTHONPATH=. python benchmarks/friction_speed.py", _friction_ringdown_rows),
)


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _num(text: str, digits: int = 3) -> str:
    try:
        v = float(text)
    except (TypeError, ValueError):
        return text or ""
    return f"{v:.{digits}g}"


def _machine(folder: Path, name: str | None) -> str:
    if name is None or not (folder / name).exists():
        return "machine recorded in the benchmark's own CSV"
    kv = {r["key"]: r["value"] for r in _read(folder / name)}
    keys = ("cpu", "cores", "python", "numpy", "scipy", "numba", "scikit-fem", "git_commit", "date_utc",
            "load_1min_start", "load_1min")
    return ", ".join(f"{k} {kv[k]}" for k in keys if k in kv)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folder", default=str(ROOT / "results" / "performance"))
    folder = Path(ap.parse_args().folder)
    rows, missing, machines = [], [], []
    for headline, machine, topic, command, meaning in SOURCES:
        path = folder / headline
        if not path.exists():
            missing.append((headline, command))
            continue
        for r in _read(path):
            row = {"benchmark": topic, **{c: r.get(c, "") for c in COLUMNS}, "processes": r.get("processes", ""),
                   "command": command}
            if meaning and _num(row["error"]) != row["error"]:  # a bare number: say what it is
                row["error"] = f"{meaning}: {_num(row['error'])}"
            rows.append(row)
        machines.append((topic, _machine(folder, machine)))
    for sub, topic, command, read in OWN_TABLES:
        try:
            got = read(folder.parent)
        except (OSError, KeyError, StopIteration, ValueError) as exc:
            missing.append((f"results/{sub} ({type(exc).__name__}: {exc})", command))
            continue
        rows += [{"benchmark": topic, **r, "processes": "", "command": command} for r in got]
        machines.append((topic, f"recorded in results/{sub}/"))
    write_rows(folder / "summary.csv", rows)

    lines = ["# Performance", "",
             "Every headline speed figure of the project, regenerated by `python benchmarks/performance_summary.py` "
             "from the tables the benchmarks write (`summary.csv` holds the same rows). Each ratio is "
             "baseline time / our time, measured in one session on the same machine, medians of at least "
             "3 runs; the baseline column names what we ran against. Timings depend on the machine and its "
             "load: the tests assert none of them.", "",
             "| benchmark | what | ours (s) | baseline | baseline (s) | ratio | target | met |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        what = r["what"].replace("|", "/")
        lines.append(f"| {r['benchmark']} | {what} | {_num(r['ours_s'])} | {r['baseline'] or '-'} | "
                     f"{_num(r['baseline_s'])} | {_num(r['ratio'])} | {r['target'] or '-'} | "
                     f"{'yes' if r['met'] == 'True' else 'no' if r['met'] == 'False' else '-'} |")
    lines += ["", "## Accuracy at those speeds", ""]
    lines += [f"- {r['what']}: {r['error']}" for r in rows if r["error"]]
    several = [r for r in rows if r["processes"]]
    if several:
        lines += ["", "## Rows measured in several processes", "",
                  "Each is the row of the median process (benchmarks/process_median.py, Caveats); the number that "
                  "decides it in every process, and each process's speed probe at its start and end:", ""]
        lines += [f"- {_short(r['what'])}: {r['processes']}" for r in several]
    lines += ["", "## Targets not met", ""]
    unmet = [r for r in rows if r["met"] == "False"]
    said = set()
    for r in unmet:
        why = next((text for start, text in LIMITS if r["what"].startswith(start)), "not analysed")
        said_why = "as in the row above" if why in said and why != "not analysed" else why
        said.add(why)
        lines.append(f"- {r['what']}: {_num(r['ours_s'])} s against {r['target']}. What limits it: {said_why}.")
    if not unmet:
        lines.append("- none")
    lines += ["", "## Caveats", ""]
    lines += [f"- {text}" for text in CAVEATS]
    lines += ["", "## The same code on another machine", "",
              "Absolute times and even the ratios against a Python-level baseline move with the machine "
              "(our numba kernels and SciPy's Python-level DOP853 do not speed up alike). On an earlier machine "
              "of the same kind, against the table above:", ""]
    lines += [f"- {text}" for text in EARLIER_MACHINE]
    lines += ["", "## How each was measured", ""]
    lines += [f"- {topic}: `{command}`" for _, _, topic, command, _ in SOURCES]
    lines += [f"- {topic}: `{command}`" for _, topic, command, _ in OWN_TABLES]
    lines += ["", "## Machines", ""]
    lines += [f"- {topic}: {m}" for topic, m in machines]
    if missing:
        lines += ["", "## Not measured", ""]
        lines += [f"- {h}: run `{c}`" for h, c in missing]
    (folder / "README.md").write_text("\n".join(lines) + "\n")
    print(f"{len(rows)} rows in {folder / 'summary.csv'}; {len(unmet)} targets not met; "
          f"{len(missing)} headline files missing")


if __name__ == "__main__":
    main()
