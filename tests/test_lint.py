"""The source tree passes ruff (the style the project agreed on in pyproject.toml)."""

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_clean():
    # ruff is a test dependency (pyproject.toml, the [test] extra): call it through the
    # interpreter running pytest, so the test runs whether or not a ruff executable is on
    # PATH (shutil.which("ruff") was None under `python -m pytest` without an activated venv,
    # and the test was always skipped). A missing ruff is a broken test install: fail, not skip.
    assert importlib.util.find_spec("ruff") is not None, 'ruff is not installed: pip install -e ".[test]"'
    out = subprocess.run([sys.executable, "-m", "ruff", "check", "--quiet", str(ROOT)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
