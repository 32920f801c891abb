"""Fill the reduced-model cache for every built-in scene with a reduced model: its reduction and the full 3-D
model's open- and closed-gap modes (what ``reduce`` and ``verify`` load), and with ``[hammer] linear_check`` the
full model's modes of that check (:func:`bearingshaft.stages.hammer_linear.full_modes`), and with ``[frf]`` the
3-D model's MAC reference (:func:`bearingshaft.stages.frf.fe_reference`), and the ``reduce`` stage's
``gap_modes.png`` (the figure cache of :func:`bearingshaft.render.render_shapes`), so that a timed
``bearingshaft run`` measures the job with its reductions cached, as ``benchmarks/job_times.py`` reports it (the
modal stages' ``mode_shapes.png`` are drawn by the first run and copied by the next).

    PYTHONPATH=. python benchmarks/warm_cache.py

Prints each scene with "built" or "cached" and its time. A scene whose ``rom_file`` names a saved model is skipped.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> int:
    import tempfile

    import bearingshaft.scenes as scenes
    from bearingshaft.gap_modes import full_gap_modes
    from bearingshaft.registry import stages_of
    from bearingshaft.render import render_shapes
    from bearingshaft.scenes import load_scene
    from bearingshaft.stages.frf import fe_reference
    from bearingshaft.stages.hammer_linear import full_modes
    from bearingshaft.stages.reduce import compute as reduce_compute
    from reduced.models.rom import RomSpec, from_cache, reduction, store_in_cache

    for path in sorted(Path(scenes.__file__).parent.glob("*.toml")):
        scene = load_scene(path.stem)
        spec = scene.model
        if not isinstance(spec, RomSpec) or spec.rom_file:
            continue
        t0 = time.perf_counter()
        had = from_cache(spec) is not None
        rom, fe = reduction(spec)
        if not had:
            store_in_cache(rom, spec)
        full_gap_modes(fe, spec, Psi=rom.Psi)
        if scene.hammer is not None and scene.hammer.linear_check:
            full_modes(fe, scene.hammer.linear_check_max_hz, progress=False)
        if scene.frf is not None and scene.frf.mac_reference == "fe":
            fe_reference(spec.fe_model(), scene.frf.fe_modes)
        if "reduce" in stages_of(scene):
            reduced = reduce_compute(scene, False, None)
            with tempfile.TemporaryDirectory() as tmp:
                render_shapes(reduced.fe, reduced.mode_shapes, Path(tmp) / "gap_modes.png")
        print(f"{path.stem}: {'cached' if had else 'built'} in {time.perf_counter() - t0:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
