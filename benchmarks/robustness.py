"""Bad input tried as a user would: every class of issue 10, run through the real command.

Each case runs ``bearingshaft`` in a fresh process (real exit code, real stderr) and is
"refused cleanly" when it exits 2 with exactly one line on stderr, no traceback, and no
results folder. The scene-mutation classes run every key of every built-in scene through
``bearingshaft check`` in this process (the same parser and checks, no solving). Writes
``results/robustness/cases.csv`` (one row per case) and ``results/robustness/README.md``
(one row per class).

    python benchmarks/robustness.py
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import re
import subprocess
import sys
import tempfile
import tomllib
from collections import Counter
from importlib import resources
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "results" / "robustness"
TIMEOUT_S = 120

DISCRETE = """[model]
kind = "discrete"
[ringdown]
duration_s = 0.01
"""


def _cli(args: list[str], env: dict | None = None) -> tuple[int, str]:
    try:
        proc = subprocess.run([sys.executable, "-c", "import sys; from bearingshaft.cli import main; "
                               "sys.exit(main(sys.argv[1:]))", *args], capture_output=True, text=True,
                              timeout=TIMEOUT_S, env={**os.environ, **(env or {})})
    except subprocess.TimeoutExpired:
        return -1, f"still running after {TIMEOUT_S} s (accepted)"
    return proc.returncode, proc.stderr


def _verdict(rc: int, err: str, out: Path | None) -> str:
    lines = err.strip().splitlines()
    if "Traceback" in err:
        return "traceback"
    if rc != 2:
        return f"exit {rc}"
    if len(lines) != 1:
        return f"{len(lines)} lines"
    if out is not None and out.exists():
        return "folder written"
    return "refused"


def scene_case(tmp: Path, text: str, stage: str = "ringdown", out: Path | None = None) -> tuple[str, str]:
    path = tmp / "case.toml"
    path.write_text(text)
    out = out or tmp / "results"
    rc, err = _cli([stage, "--scene", str(path), "--out", str(out), "--no-progress"])
    return _verdict(rc, err, out), err.strip()


def file_cases(tmp: Path) -> list[tuple[str, str, str, str]]:
    """(class, case, verdict, message) for the hand-written cases of the issue."""
    rows = []

    def add(cls, name, verdict_msg):
        rows.append((cls, name, *verdict_msg))

    types = {
        "kind as a list": '[model]\nkind = ["discrete"]\n[ringdown]\n',
        "kind as a table": "[model.kind]\na = 1\n[ringdown]\n",
        "model as a scalar": "model = 3\n[ringdown]\n",
        "number as a string": DISCRETE + 'sample_rate_hz = "20000"\n',
        "number as a boolean": DISCRETE + "sample_rate_hz = true\n",
        "integer as a float": '[model]\nkind = "discrete"\n[nnm]\nn_energy = 40.0\n',
        "duplicated table": DISCRETE + "[ringdown]\n",
        "misspelled key": DISCRETE + "sample_rate = 100.0\n",
        "misspelled table": DISCRETE + "[ringdwn]\n",
        "not TOML": "[model\n",
        "NaN": "[model]\nkind = \"discrete\"\nk_g = nan\n[ringdown]\n",
        "inf": "[model]\nkind = \"discrete\"\ng = inf\n[ringdown]\n",
        "negative mass": "[model]\nkind = \"discrete\"\nm1 = -1.0\n[ringdown]\n",
    }
    for name, text in types.items():
        add("wrong types and keys", name, scene_case(tmp, text))
    sizes = {
        "duration_s = 1e6": DISCRETE.replace("0.01", "1e6"),
        "sample_rate_hz = 1e12": DISCRETE + "sample_rate_hz = 1e12\n",
        "harmonics = [5000]": '[model]\nkind = "discrete"\n[nnm]\n[fep]\nharmonics = [5000]\n',
        "n_energy = 1e9": '[model]\nkind = "discrete"\n[nnm]\nn_energy = 1000000000\n',
        "stiff_cases duration_s = 1e7": '[model]\nkind = "discrete"\n[stiff_cases]\nduration_s = 1e7\n',
    }
    for name, text in sizes.items():
        stage = "nnm" if "[nnm]" in text else "study" if "stiff" in text else "ringdown"
        add("sizes that cannot fit", name, scene_case(tmp, text, stage))
    add("missing tables", "[fep] without [nnm]",
        scene_case(tmp, '[model]\nkind = "discrete"\n[fep]\n', "nnm"))
    add("missing tables", "[spectrogram] without [ringdown]",
        scene_case(tmp, '[model]\nkind = "discrete"\n[spectrogram]\n[nnm]\n', "nnm"))
    wrong = {
        "explicit dt above the stability limit": DISCRETE + 'method = "explicit"\ndt_s = 1e-3\n',
        "explicit omega_dt = 3": DISCRETE + 'method = "explicit"\nomega_dt = 3.0\n',
        "stiff_cases negative k_g": '[model]\nkind = "discrete"\n[stiff_cases]\nk_g = [-1e7]\n',
        "stiff_cases negative gap": '[model]\nkind = "discrete"\n[stiff_cases]\ngap = [-1e-4]\n',
        "stiff_cases negative damping": '[model]\nkind = "discrete"\n[stiff_cases]\nc = [-4.0]\n',
        "stiff_cases empty list": '[model]\nkind = "discrete"\n[stiff_cases]\nk_g = []\n',
        "work_precision rtol >= 1": '[model]\nkind = "discrete"\n[work_precision]\ndop853_rtol = [1.0, 1e-6]\n',
        "ringdown rtol >= 1": DISCRETE + 'method = "dop853"\nrtol = 2.0\n',
    }
    for name, text in wrong.items():
        add("accepted before, wrong", name, scene_case(tmp, text, "study" if "[model]\nkind = \"discrete\"\n[" in
                                                       text and "ringdown" not in text else "ringdown"))
    # --out
    afile = tmp / "afile"
    afile.write_text("x")
    scene = tmp / "ok.toml"
    scene.write_text(DISCRETE)
    for name, out in {"an existing file": afile, "a path under a file": afile / "sub", "/dev/null": Path("/dev/null"),
                      "a folder under /proc": Path("/proc/bs-robustness/out"),
                      "a read-only folder (/sys)": Path("/sys/kernel/bs-robustness")}.items():
        rc, err = _cli(["ringdown", "--scene", str(scene), "--out", str(out), "--no-progress"])
        add("--out", name, (_verdict(rc, err, None if out.exists() else out), err.strip()))
    # scene names
    rc, err = _cli(["ringdown", "--scene", "discrete-impulze"])
    add("scene names", "misspelled built-in scene", (_verdict(rc, err, None), err.strip()))
    rc, err = _cli(["ringdown", "--scene", str(tmp / "missing.toml")])
    add("scene names", "missing scene file", (_verdict(rc, err, None), err.strip()))
    binary = tmp / "binary.toml"
    binary.write_bytes(bytes(range(256)))
    rc, err = _cli(["ringdown", "--scene", str(binary)])
    add("scene names", "binary scene file", (_verdict(rc, err, None), err.strip()))
    return rows


def _test_channels(n: int = 4000, dt: float = 5e-5):
    """A small valid hammer test: the hammer (a 1 ms half-sine of 500 N at 10 ms) and a triaxial
    beam accelerometer, as a user's file would hold them."""
    import numpy as np

    from fem.uff import TimeHistory

    t = np.arange(n) * dt
    hammer = np.where((t >= 0.01) & (t <= 0.011), 500.0 * np.sin(np.pi * (t - 0.01) / 1e-3), 0.0)
    acc = [TimeHistory(f"beam_s1:{a}", 1, d, "acceleration", np.sin(2 * np.pi * 731 * t) * np.exp(-3 * t) / d, dt)
           for d, a in ((1, "x"), (2, "y"), (3, "z"))]
    return [TimeHistory("hammer", 300, -3, "force", hammer, dt), *acc]


def test_file_cases(tmp: Path) -> list[tuple[str, str, str, str]]:
    """A measured test's file as user input (issue 26): ``hammer --scene hammer-test --test FILE``
    refused in one line naming the record (or the file, for what concerns it whole), exit 2,
    nothing written; a case whose message misses its words is "record not named"."""
    from dataclasses import replace

    from fem.uff import write_uff58

    base = _test_channels()
    files: dict[str, tuple[object, list[str]]] = {}

    def noisy_double_hit(chs):
        d = chs[0].data.copy()
        d[1000:1010] += 150.0
        return [replace(chs[0], data=d), *chs[1:]]

    cases = {
        "channels with different sampling": ([*base[:3], replace(base[3], dt_s=1e-4)],
                                             ["record 4 ('beam_s1:z')", "sampled at 10000 Hz"]),
        "missing hammer channel": (base[1:], ["no hammer channel"]),
        "two records for one channel (same name)": ([*base, replace(base[1], node=7)],
                                                    ["record 5 ('beam_s1:x')", "two records for one channel"]),
        "two records for one channel (same node and axis)": ([*base, replace(base[3], name="acc z", direction=-3)],
                                                             ["record 5 ('acc z')", "record 4 ('beam_s1:z')"]),
        "two hammer channels": ([*base, replace(base[0], name="hammer 2", node=301)],
                                ["record 5 ('hammer 2')", "second force channel"]),
        "a channel starting later": ([*base[:2], replace(base[2], t0_s=1e-3), base[3]],
                                     ["record 3 ('beam_s1:y')", "starts at"]),
        "a record cut short": ([*base[:3], replace(base[3], data=base[3].data[:3000])],
                               ["record 4 ('beam_s1:z')", "3000 samples"]),
        "a double hit": (noisy_double_hit(base), ["record 1 ('hammer')", "double hit"]),
    }
    for name, (chs, words) in cases.items():
        path = tmp / f"{name.replace(' ', '_')}.uff"
        write_uff58(path, chs)
        files[name] = (path, words)
    good = tmp / "good.uff"
    write_uff58(good, base)
    cut = tmp / "truncated.uff"
    cut.write_bytes(good.read_bytes()[: int(0.8 * good.stat().st_size)])
    files["truncated file"] = (cut, ["truncated"])
    asc = tmp / "ascii.uff"
    write_uff58(asc, base, binary=False)
    text = asc.read_text()
    units = tmp / "units.uff"  # the y accelerometer's unit label edited to g
    i = text.index("beam_s1:y")
    units.write_text(text[:i] + text[i:].replace("m/s^2", "g    ", 1))
    files["units that do not match"] = (units, ["record 3 (beam_s1:y)", "'g'", "m/s^2"])
    marked = base[2].data.copy()
    marked[1234] = 12345.0  # a value whose text is found and replaced (pyuff writes a NaN as 0)
    write_uff58(asc, [*base[:2], replace(base[2], data=marked), base[3]], binary=False)
    nan = tmp / "nan.uff"
    value = "1.23450000000e+04"
    nan.write_text(asc.read_text().replace(value, "NaN".rjust(len(value)), 1))
    files["NaN samples"] = (nan, ["record 3 ('beam_s1:y')", "not finite", "t = 0.0617 s"])
    rows = []
    for name, (path, words) in files.items():
        out = tmp / f"out-{path.stem}"
        rc, err = _cli(["hammer", "--scene", "hammer-test", "--test", str(path), "--out", str(out), "--no-progress"])
        verdict = _verdict(rc, err, out)
        if verdict == "refused" and not all(w in err for w in words):
            verdict = "record not named"
        rows.append(("test files", name, verdict, err.strip()))
    return rows


def python_api_cases() -> list[tuple[str, str, str, str]]:
    """Python API calls with bad arguments: a ValueError naming the argument, at once."""
    import time

    import numpy as np

    from reduced import DiscreteParams, ringdown

    system = DiscreteParams().system()
    x0, v0 = np.zeros(3), np.array([0.0, 0.0, 20.0])
    calls = {
        "dop853 atol = NaN": dict(method="dop853", atol=float("nan")),
        "dop853 rtol = NaN": dict(method="dop853", rtol=float("nan")),
        "dop853 rtol = 1": dict(method="dop853", rtol=1.0),
        "explicit dt = NaN": dict(method="explicit", dt=float("nan")),
        "explicit dt = 1e-3 (unstable)": dict(method="explicit", dt=1e-3),
        "explicit omega_dt = -1": dict(method="explicit", omega_dt=-1.0),
        "unknown method": dict(method="rk4"),
    }
    rows = []
    for name, kw in calls.items():
        t0 = time.perf_counter()
        try:
            ringdown(system, x0, v0, 0.01, 2000.0, **kw)
            verdict, msg = "accepted", ""
        except ValueError as exc:
            msg = str(exc)
            arg = [k for k, v in kw.items() if k != "method" or v == "rk4"][0]
            one = len(msg.splitlines()) == 1 and arg in msg
            verdict = "refused" if one and time.perf_counter() - t0 < 5 else "unclear message"
        except Exception as exc:  # noqa: BLE001 - the point is to record it
            verdict, msg = type(exc).__name__, str(exc)
        rows.append(("Python API", name, verdict, msg))
    return rows


def mutation_cases() -> list[tuple[str, str, str, str]]:
    """Every key of every built-in scene, each always-invalid mutation, through ``check``."""
    import tomli_w

    from bearingshaft.cli import main
    from bearingshaft.scenes import SECTIONS, builtin_names, model_class

    kinds = {"wrong type: string": "abc", "wrong type: boolean": True, "wrong type: table": {"a": 1},
             "NaN": float("nan"), "+inf": float("inf"), "-inf": float("-inf")}
    rows = []
    for scene in builtin_names():
        data0 = tomllib.loads((resources.files("bearingshaft") / "scenes" / f"{scene}.toml").read_text())
        tables = {t: SECTIONS[t] for t in data0 if t in SECTIONS}
        tables["model"] = model_class(data0.get("model", {}).get("kind", "discrete"))
        for table, cls in tables.items():
            for f in cls.__dataclass_fields__.values():
                for kind, value in kinds.items():
                    if kind == "wrong type: string" and "str" in str(f.type):
                        value = 3.5
                    if kind == "wrong type: boolean" and str(f.type) == "bool":
                        value = 1.0
                    data = tomllib.loads(tomli_w.dumps(data0))
                    data.setdefault(table, {})[f.name] = value
                    with tempfile.TemporaryDirectory() as tmp:
                        path = Path(tmp) / "case.toml"
                        path.write_text(tomli_w.dumps(data))
                        out = Path(tmp) / "out"
                        err = io.StringIO()
                        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                            try:
                                rc = main(["check", "--scene", str(path), "--out", str(out)])
                            except Exception:  # noqa: BLE001
                                rc, err = 1, io.StringIO("Traceback")
                        verdict = _verdict(rc, err.getvalue(), out)
                        if verdict == "refused" and f.name not in err.getvalue():
                            verdict = "key not named"
                    rows.append((f"scene mutation: {kind}", f"{scene} [{table}] {f.name}", verdict,
                                 err.getvalue().strip()))
    return rows


def cache_cases(tmp: Path) -> list[tuple[str, str, str, str]]:
    """A reduced model's cache entry truncated, emptied or garbled: reported and rebuilt (exit 0)."""
    scene = tmp / "rom.toml"
    scene.write_text('[model]\nkind = "rom"\nn_modes = 1\nelement_size = 0.3\n[ringdown]\nduration_s = 0.005\n')
    cache = tmp / "cache"
    env = {"BEARINGSHAFT_CACHE": str(cache)}
    rc, err = _cli(["ringdown", "--scene", str(scene), "--out", str(tmp / "r0"), "--no-progress"], env)
    if rc != 0:
        return [("corrupt cache", "first build", f"exit {rc}", err.strip().splitlines()[-1:] and err)]
    rows = []
    entries = sorted(cache.glob("rom-*.npz"))
    def flip(b: bytes) -> bytes:
        i = len(b) // 2
        return b[:i] + bytes([b[i] ^ 0xFF]) + b[i + 1:]

    for name, damage in {"truncated": lambda b: b[: len(b) // 2], "zero-length": lambda b: b"",
                         "bit-flipped": flip}.items():
        for entry in entries:
            entry.write_bytes(damage(entry.read_bytes()))
        rc, err = _cli(["ringdown", "--scene", str(scene), "--out", str(tmp / f"r-{name}"), "--no-progress"], env)
        lines = err.strip().splitlines()
        ok = rc == 0 and "Traceback" not in err and len(lines) == 1 and "corrupt" in err.lower()
        rows.append(("corrupt cache", name, "reported and rebuilt" if ok else f"exit {rc}, {len(lines)} lines",
                     err.strip()))
        entries = sorted(cache.glob("rom-*.npz"))
    return rows


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        rows = (file_cases(Path(tmp)) + test_file_cases(Path(tmp)) + python_api_cases() + cache_cases(Path(tmp))
                + mutation_cases())
    # temporary paths differ from run to run: the record keeps what the user would read
    rows = [(c, k, v, re.sub(r"/tmp/[^/ ]+", "<tmp>", m)) for c, k, v, m in rows]
    with open(OUT / "cases.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["class", "case", "verdict", "message"])
        w.writerows(rows)
    total = Counter(r[0] for r in rows)
    clean = Counter(r[0] for r in rows if r[2] in ("refused", "reported and rebuilt"))
    lines = ["# Robustness: bad input tried, and how it was refused", "",
             "Regenerated by `python benchmarks/robustness.py`. A case is refused cleanly when the command",
             "exits 2 with one line on stderr (naming the key), no traceback and no results folder; a corrupt",
             "cache entry is reported in one line and rebuilt (exit 0); a bad Python API argument raises a one-line",
             "ValueError naming it; a bad test file (`hammer --test`) is refused so and its message names the record.",
             "Every case is listed in `cases.csv`.", "",
             "| class | cases | refused cleanly |", "|---|---:|---:|"]
    lines += [f"| {c} | {total[c]} | {clean[c]} |" for c in total]
    lines += ["", f"All: {sum(clean.values())} of {sum(total.values())} refused cleanly.", ""]
    bad = [r for r in rows if r[2] not in ("refused", "reported and rebuilt")]
    if bad:
        lines += ["Not refused cleanly:", ""] + [f"- {r[0]}: {r[1]}: {r[2]} ({r[3][:200]})" for r in bad] + [""]
    (OUT / "README.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
