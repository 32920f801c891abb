"""Results folders: written whole or not at all, each with its case and provenance.

A stage writes into a scratch folder beside the results folder; only when the stage
finishes are its files moved in and ``provenance.json`` updated (PyFR keeps the config
and statistics with each solution in the same way). A failed stage leaves the results
folder as it was, never a half-written set of files that looks complete.
"""

from __future__ import annotations

import csv
import json
import platform
import shutil
import subprocess
import tempfile
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from bearingshaft import __version__


def git_commit() -> str:
    """The commit of the source tree this package runs from ('unknown' outside git)."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()
        # changes under results/ (the tool's own output) do not make the source dirty
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)results"],
            cwd=here.parent, capture_output=True, text=True, timeout=5, check=True,
        ).stdout.strip()
        return out + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return str(obj)
    return obj


def write_rows(path: str | Path, rows: list[dict], fields: list[str] | None = None,
               float_format: str | None = None) -> None:
    """CSV of dict rows; columns ``fields`` (default: the first row's keys; others dropped);
    floats written with ``float_format`` (e.g. ".4g") if given, else in full."""
    with open(path, "w", newline="") as fh:
        if not rows and fields is None:
            return
        w = csv.DictWriter(fh, fieldnames=fields or list(rows[0]), extrasaction="ignore")
        w.writeheader()
        if float_format is None:
            w.writerows(rows)
        else:
            w.writerows({k: format(v, float_format) if isinstance(v, float) else v for k, v in r.items()}
                        for r in rows)


class StageWriter:
    """Where a stage puts its files (``path(name)``) and its solver statistics (``stats``)."""

    def __init__(self, scratch: Path) -> None:
        self.scratch = scratch
        self.stats: dict = {}

    def path(self, name: str) -> Path:
        return self.scratch / name


@contextmanager
def staged_output(out_dir: str | Path, scene_name: str, scene_source: str, stage: str):
    """Yield a :class:`StageWriter`; on success move its files into ``out_dir``.

    ``out_dir`` also receives ``scene.toml`` (the case as read) and ``provenance.json``
    (package version, git commit, platform, and per-stage statistics and file lists).
    """
    out = Path(out_dir)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f".{stage}.partial-", dir=out))
    writer = StageWriter(scratch)
    try:
        try:
            yield writer
        except BaseException:
            shutil.rmtree(scratch, ignore_errors=True)
            if created and not any(out.iterdir()):
                out.rmdir()  # a first run that failed leaves no folder behind
            raise
        files = sorted(p.name for p in scratch.iterdir())
        for name in files:
            target = out / name
            if target.is_dir():
                shutil.rmtree(target)
            (scratch / name).replace(target)
        (out / "scene.toml").write_text(scene_source, encoding="utf-8")
        prov_path = out / "provenance.json"
        prov = json.loads(prov_path.read_text()) if prov_path.exists() else {}
        prov.update(
            {
                "scene": scene_name,
                "package": "bearingshaft",
                "version": __version__,
                "git_commit": git_commit(),
                "python": platform.python_version(),
                "numpy": np.__version__,
                "machine": platform.machine(),
            }
        )
        prov.setdefault("stages", {})[stage] = {
            "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "files": files,
            "stats": _jsonable(writer.stats),
        }
        tmp = prov_path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(prov, indent=2, sort_keys=True) + "\n", encoding="utf-8")
        tmp.replace(prov_path)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
