"""Checked cache entries (reduced.cache) and the reduced-model cache built on them."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import reduced.models.rom as rom_module
from bearingshaft.cli import main
from reduced.cache import cached_arrays, hash_sparse, load_entry, manifest_path, write_entry
from reduced.models.rom import ReducedModel, RomSpec, build_rom, cached_rom, store_in_cache

# 729 DOFs (hex8, coarse), 2 fixed-interface modes: built in about 0.5 s
SPEC = RomSpec(n_modes=2, element="hex8", element_size=0.5)
ARRAYS = ("M", "K", "C", "P", "omega_fixed", "Psi", "Phi")


@pytest.fixture(scope="module")
def fresh():
    return build_rom(SPEC)[0]


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache folder, and a count of the reduced models built."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(folder))
    builds = []

    def counting_build(spec, fe=None, progress=False):
        builds.append(spec)
        return build_rom(spec, fe, progress)

    monkeypatch.setattr(rom_module, "build_rom", counting_build)
    return folder, builds


def _same(a: ReducedModel, b: ReducedModel) -> bool:
    # the same build of the same spec: the same floating-point operations, so equal bit for bit
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ARRAYS) and a.dof_names == b.dof_names


def _flip(path, where: float = 0.5) -> None:
    data = bytearray(path.read_bytes())
    i = int(where * len(data))
    data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def _corrupt_reports(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "reduced.cache"]


def test_an_entry_is_stored_with_its_manifest_and_read_back_without_a_build(cache, fresh):
    folder, builds = cache
    first = cached_rom(SPEC)
    assert len(builds) == 1 and _same(first, fresh)
    entry = rom_module._cache_path(SPEC)
    assert entry.parent == folder and entry.name.startswith("rom-") and entry.suffix == ".npz"
    manifest = json.loads(manifest_path(entry).read_text())
    assert manifest["sha256"] == hashlib.sha256(entry.read_bytes()).hexdigest()
    assert manifest["size"] == entry.stat().st_size
    assert manifest["inputs_sha256"] == rom_module._inputs_hash(SPEC)
    assert manifest["inputs_sha256"].startswith(entry.name[4:24])  # the key is its first 20 digits
    assert manifest["info"]["spec"]["n_modes"] == 2
    assert sorted(p.name for p in folder.iterdir()) == sorted([entry.name, entry.name + ".json", ".cache.lock"])
    again = cached_rom(RomSpec(n_modes=2, element="hex8", element_size=0.5, k_g=1e9))
    assert len(builds) == 1 and _same(again, fresh)
    assert again.k_g == 1e9  # the contact is applied after loading: same entry, no rebuild


def _truncate(entry):
    entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 2])


def _empty(entry):
    entry.write_bytes(b"")


def _flip_data(entry):
    _flip(entry)


def _flip_manifest(entry):
    _flip(manifest_path(entry))


def _other_inputs(entry):
    m = json.loads(manifest_path(entry).read_text())
    m["inputs_sha256"] = hashlib.sha256(b"another spec").hexdigest()
    manifest_path(entry).write_text(json.dumps(m))


def _no_manifest(entry):
    manifest_path(entry).unlink()


def _no_data(entry):
    entry.unlink()


def _flip_data_keep_checksum(entry):
    # a bad file that its manifest vouches for: the decoder's own error must be caught
    _flip(entry)
    m = json.loads(manifest_path(entry).read_text())
    m["sha256"] = hashlib.sha256(entry.read_bytes()).hexdigest()
    manifest_path(entry).write_text(json.dumps(m))


@pytest.mark.parametrize(
    ("damage", "reason"),
    [
        (_truncate, "bytes, manifest says"),
        (_empty, "0 bytes, manifest says"),
        (_flip_data, "sha256 differs"),
        (_flip_manifest, "manifest unreadable"),  # 0xFF in the middle of the JSON: not UTF-8
        (_other_inputs, "input hash differs"),
        (_no_manifest, "no manifest"),
        (_no_data, "manifest without its data file"),
        (_flip_data_keep_checksum, "cannot be read"),
    ],
)
def test_a_damaged_entry_is_reported_in_one_line_removed_and_rebuilt(cache, fresh, caplog, damage, reason):
    folder, builds = cache
    cached_rom(SPEC)
    entry = rom_module._cache_path(SPEC)
    damage(entry)
    with caplog.at_level(logging.WARNING, logger="reduced.cache"):
        rebuilt = cached_rom(SPEC)
    assert len(builds) == 2, "a damaged entry must be rebuilt"
    assert _same(rebuilt, fresh)
    reports = _corrupt_reports(caplog)
    assert len(reports) == 1 and "\n" not in reports[0], reports
    assert reports[0].startswith(f"cache entry {entry} is corrupt (") and reports[0].endswith("); rebuilding")
    assert reason in reports[0]
    # stored again, intact: the next read neither reports nor builds
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="reduced.cache"):
        assert _same(cached_rom(SPEC), fresh)
    assert len(builds) == 2 and not _corrupt_reports(caplog)


def test_decoder_errors_of_every_kind_count_as_corrupt(tmp_path, caplog):
    import struct
    import zlib
    from zipfile import BadZipFile

    for exc in (BadZipFile("File is not a zip file"), zlib.error("Error -3 while decompressing data"),
                EOFError(), UnicodeDecodeError("utf-8", b"\xff", 0, 1, "invalid start byte"),
                struct.error("unpack requires a buffer of 4 bytes"), KeyError("M")):
        entry = tmp_path / "thing.bin"
        write_entry(entry, lambda f: f.write(b"payload"), "inputs")

        def decode(f, exc=exc):
            assert f.read() == b"payload"  # the decoder gets exactly the checked bytes
            raise exc

        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="reduced.cache"):
            assert load_entry(entry, "inputs", decode) is None
        (report,) = _corrupt_reports(caplog)
        assert type(exc).__name__ in report and "\n" not in report
        assert not entry.exists() and not manifest_path(entry).exists()
    assert load_entry(tmp_path / "absent.bin", "inputs", bytes) is None  # a miss is not reported
    assert not _corrupt_reports(caplog)[1:]


def test_cached_arrays_compute_once_then_load_the_same_bits(tmp_path, monkeypatch):
    """cached_arrays: a miss computes and stores, a hit returns the stored bits without computing, another
    input hash is another entry, a damaged entry is computed again, and a folder that cannot be written only
    costs a computation."""
    calls = []
    rng = np.random.default_rng(3)
    made = {"phi": rng.standard_normal((5, 3)), "n": np.int64(7)}

    def compute():
        calls.append(1)
        return {k: np.copy(v) for k, v in made.items()}

    entry = tmp_path / "x-key.npz"
    first = cached_arrays(entry, "key", compute, info={"kind": "test"})
    again = cached_arrays(entry, "key", compute)
    assert len(calls) == 1 and set(again) == {"phi", "n"}
    assert np.array_equal(again["phi"], made["phi"]) and again["phi"].tobytes() == first["phi"].tobytes()
    assert int(again["n"]) == 7 and json.loads(manifest_path(entry).read_text())["info"] == {"kind": "test"}
    cached_arrays(entry, "other", compute)  # another input hash: computed again, the entry replaced
    assert len(calls) == 2
    entry.write_bytes(entry.read_bytes()[:-9])  # truncated: its sha256 no longer matches
    assert np.array_equal(cached_arrays(entry, "other", compute)["phi"], made["phi"]) and len(calls) == 3

    def refuse(*args, **kwargs):
        raise PermissionError("read-only")

    monkeypatch.setattr("reduced.cache.write_entry", refuse)
    out = cached_arrays(tmp_path / "y.npz", "key", compute)
    assert np.array_equal(out["phi"], made["phi"]) and len(calls) == 4 and not (tmp_path / "y.npz").exists()


def test_hash_sparse_tells_matrices_apart_by_their_bits():
    import scipy.sparse as sp

    A = sp.random(30, 30, density=0.1, random_state=1, format="csr")

    def digest(*ms):
        h = hashlib.sha256()
        hash_sparse(h, *ms)
        return h.hexdigest()

    assert digest(A, A.T) == digest(A.tocoo(), A.T.tocsc())  # the same matrices in other formats
    B = A.copy()
    B.data[0] = np.nextafter(B.data[0], 1.0)  # one ulp in one entry
    assert digest(A, A.T) != digest(B, A.T) and digest(A, A.T) != digest(A.T, A)


def test_the_corruption_report_is_one_line_on_stderr(tmp_path):
    # outside pytest's log capture: logging's last-resort handler prints the message alone
    entry = tmp_path / "thing.bin"
    write_entry(entry, lambda f: f.write(b"payload"), "inputs")
    _flip(entry)
    code = ("from reduced.cache import load_entry\n"
            f"assert load_entry({str(entry)!r}, 'inputs', lambda f: f.read()) is None\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stderr == f"cache entry {entry} is corrupt (sha256 differs from the manifest's); rebuilding\n"


@pytest.mark.parametrize("damage", [_truncate, _empty, _flip_data, lambda p: p.write_bytes(b"not a file")])
def test_a_corrupt_rom_file_is_refused_naming_rom_file(tmp_path, fresh, damage):
    path = tmp_path / "rom.npz"
    fresh.save(path)
    damage(path)
    with pytest.raises(ValueError, match=r"^rom_file: .*rom\.npz: not a reduced model file \(") as err:
        RomSpec(rom_file=str(path)).reduced()
    assert "\n" not in str(err.value)


def test_a_corrupt_rom_file_exits_2_in_one_line(tmp_path, capsys, fresh):
    path = tmp_path / "rom.npz"
    fresh.save(path)
    _truncate(path)
    scene = tmp_path / "from-file.toml"
    scene.write_text(f'[model]\nkind = "rom"\nrom_file = "{path}"\n[initial]\nv0_m_s = [0.0, 0.0, 200.0]\n'
                     '[ringdown]\nduration_s = 0.01\n', encoding="utf-8")
    assert main(["ringdown", "--scene", str(scene), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "rom_file" in err and "not a reduced model file" in err and "\n" not in err, err
    assert not (tmp_path / "out").exists()


def test_save_leaves_no_temporary_file(tmp_path, fresh):
    fresh.save(tmp_path / "rom.npz")
    fresh.save(tmp_path / "rom.npz")  # over an existing file
    assert [p.name for p in tmp_path.iterdir()] == ["rom.npz"]
    assert _same(ReducedModel.load(tmp_path / "rom.npz"), fresh)


WRITER = """
import logging, os, sys, time
from dataclasses import replace
from pathlib import Path
logging.basicConfig(level=logging.WARNING, format="%(message)s")
from reduced.cache import load_entry
from reduced.models.rom import ReducedModel, RomSpec, _cache_path, _inputs_hash, store_in_cache
spec = RomSpec(n_modes=2, element="hex8", element_size=0.5)
rom = ReducedModel.load(sys.argv[1])
go = Path(sys.argv[2])
while not go.exists():
    time.sleep(0.002)
inputs = _inputs_hash(spec)
for i in range(int(sys.argv[3])):
    # every write differs, so data of one writer under the manifest of another would show
    store_in_cache(replace(rom, info={**rom.info, "writer": [os.getpid(), i]}), spec)
    assert load_entry(_cache_path(spec, inputs), inputs, ReducedModel.load) is not None
"""


def test_eight_processes_writing_one_entry_at_once_leave_it_valid(tmp_path, fresh, caplog):
    folder = tmp_path / "cache"
    fresh.save(tmp_path / "rom.npz")
    go = tmp_path / "go"
    env = {**os.environ, "BEARINGSHAFT_CACHE": str(folder)}
    procs = [subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path / "rom.npz"), str(go), "25"],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(8)]
    time.sleep(1.0)  # let them import and wait at the start line
    go.touch()
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, outs, strict=True):
        # a reader may meet a writer between its two renames; it looks again under the lock, so
        # no process ever finds a corrupt entry
        assert p.returncode == 0 and err == "", err
    entry = folder / f"rom-{rom_module._inputs_hash(SPEC)[:20]}.npz"
    assert sorted(p.name for p in folder.iterdir()) == sorted([entry.name, entry.name + ".json", ".cache.lock"])
    with caplog.at_level(logging.WARNING, logger="reduced.cache"):
        back = load_entry(entry, rom_module._inputs_hash(SPEC), ReducedModel.load)
    assert back is not None and _same(back, fresh) and not _corrupt_reports(caplog)


def test_a_cache_that_cannot_be_written_is_skipped(tmp_path, monkeypatch, fresh):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path / "file" / "cache"))  # under a file
    store_in_cache(fresh, SPEC)  # no error, nothing written
    assert _same(cached_rom(SPEC), fresh)  # built, not stored
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


KERNELS = """
import numba as nb


@nb.njit(cache=True)
def _square(x):
    return x * x


@nb.njit(cache=True)
def kernel(a):
    s = 0.0
    for v in a:
        s += _square(v)
    return s
"""

CALL = """
import sys
sys.path.insert(0, sys.argv[1])
import numpy as np
import nbkernels
from reduced.cache import call_numba_kernel
value = call_numba_kernel(nbkernels.kernel, np.arange(4.0))
print(value, sum(nbkernels.kernel.stats.cache_hits.values()))
"""


def _nb_file(folder, name, suffix):
    (path,) = (folder / "__pycache__").glob(f"nbkernels.{name}-*{suffix}")
    return path


def _call_kernel(folder):
    out = subprocess.run([sys.executable, "-c", CALL, str(folder)], capture_output=True, text=True, timeout=120)
    return out.returncode, out.stdout.split(), out.stderr


@pytest.fixture(scope="module")
def compiled_kernels(tmp_path_factory):
    """A module of two cache=True kernels, compiled and cached by one process."""
    folder = tmp_path_factory.mktemp("kernels")
    (folder / "nbkernels.py").write_text(KERNELS)
    assert _call_kernel(folder) == (0, ["14.0", "0"], "")  # 0 + 1 + 4 + 9; compiled
    assert _call_kernel(folder) == (0, ["14.0", "1"], "")  # from the cache
    return folder


@pytest.mark.parametrize(
    "damage",
    [
        lambda d: _truncate(_nb_file(d, "kernel", ".nbi")),
        lambda d: _nb_file(d, "kernel", ".nbc").write_bytes(bytes(range(256)) * 8),
        # the kernel recompiles, and loads its callee's cache on the way
        lambda d: (_empty(_nb_file(d, "kernel", ".nbi")), _truncate(_nb_file(d, "_square", ".nbc"))),
    ],
    ids=["index truncated", "data garbled", "callee data truncated"],
)
def test_a_corrupt_numba_cache_is_reported_and_recompiled(tmp_path, compiled_kernels, damage):
    import shutil

    work = tmp_path / "work"
    shutil.copytree(compiled_kernels, work)  # copy2 keeps the source's time stamp: the cache stays valid
    damage(work)
    code, out, err = _call_kernel(work)
    assert code == 0 and out == ["14.0", "0"], err
    assert err.startswith("numba cache of kernel in ") and err.endswith("; recompiling\n")
    assert err.count("\n") == 1, err
    assert _call_kernel(work) == (0, ["14.0", "1"], "")  # the bad files were rewritten


def test_atomic_write_gives_the_mode_of_a_plain_open(tmp_path):
    """mkstemp's 0600 would hide a results folder's rom.npz from colleagues: the file gets 0666 less the umask."""

    from reduced.cache import atomic_write, current_umask

    old = os.umask(0o027)
    try:
        assert current_umask() == 0o027
        atomic_write(tmp_path / "a.bin", lambda fh: fh.write(b"x"))
        plain = tmp_path / "b.bin"
        plain.write_bytes(b"x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.bin").stat().st_mode & 0o777 == plain.stat().st_mode & 0o777 == 0o640


# -- the mode-shape figure cache (bearingshaft.render) -------------------------------------------
def _two_cell_model():
    """Two hexahedra along x, 'beam' and 'tube', 12 nodes of 3 DOFs, and two shapes."""
    from types import SimpleNamespace

    from geometry.build import MeshData

    pts = np.array([[x, y, z] for x in (0.0, 1.0, 2.0) for y in (0.0, 0.2) for z in (0.0, 0.2)])
    idx = {tuple(p): i for i, p in enumerate(pts.tolist())}

    def hexa(x0, x1):
        return [idx[(x, y, z)] for x, y, z in ((x0, 0, 0), (x1, 0, 0), (x1, 0.2, 0), (x0, 0.2, 0),
                                               (x0, 0, 0.2), (x1, 0, 0.2), (x1, 0.2, 0.2), (x0, 0.2, 0.2))]

    mesh = MeshData(points=pts, hexes=np.array([hexa(0.0, 1.0), hexa(1.0, 2.0)]), cell_part=np.array([0, 1]),
                    part_names=("beam", "tube"), node_sets={})
    fe = SimpleNamespace(mesh=mesh, solid=SimpleNamespace(nodal_dofs=np.arange(3 * len(pts)).reshape(-1, 3).T))
    u = np.zeros(3 * len(pts))
    u[2::3] = 1.0
    return fe, [("up", u), ("tilt", u * np.repeat(pts[:, 0], 3))]


def test_the_figure_key_changes_with_every_input_it_draws_from(monkeypatch):
    """figure_key: the same inputs (copies) give the same key; one ulp of a shape or a node, a title, a cell moved
    to the other part, the DOF map, the panels a row, the renderer's source, a drawing library's version or a
    matplotlib setting each give another (a key that missed one would hand back a stale figure)."""
    from dataclasses import replace
    from types import SimpleNamespace

    import matplotlib

    import bearingshaft.render as render

    fe, shapes = _two_cell_model()
    key = render.figure_key(fe, shapes)
    assert render.figure_key(fe, [(t, u.copy()) for t, u in shapes]) == key
    u = shapes[1][1].copy()
    u[5] = np.nextafter(u[5], 2.0)
    pts = fe.mesh.points.copy()
    pts[3, 1] = np.nextafter(pts[3, 1], 1.0)
    other = [render.figure_key(fe, [shapes[0], ("tilt", u)]),
             render.figure_key(fe, [shapes[0], ("tilted", shapes[1][1])]),
             render.figure_key(fe, shapes[::-1]),
             render.figure_key(SimpleNamespace(mesh=replace(fe.mesh, points=pts), solid=fe.solid), shapes),
             render.figure_key(SimpleNamespace(mesh=replace(fe.mesh, cell_part=np.array([0, 0])), solid=fe.solid),
                               shapes),
             render.figure_key(SimpleNamespace(mesh=fe.mesh, solid=SimpleNamespace(
                 nodal_dofs=fe.solid.nodal_dofs[::-1])), shapes),
             render.figure_key(fe, shapes, columns=2)]
    with matplotlib.rc_context({"font.size": matplotlib.rcParams["font.size"] + 1}):
        other.append(render.figure_key(fe, shapes))
    import importlib.metadata as md

    real = md.version
    monkeypatch.setattr(md, "version", lambda lib: "0.0.1" if lib == "vtk" else real(lib))
    other.append(render.figure_key(fe, shapes))
    monkeypatch.setattr(md, "version", real)
    monkeypatch.setattr(render, "__file__", str(render.__file__).replace("render.py", "plots.py"))
    other.append(render.figure_key(fe, shapes))
    assert len({key, *other}) == len(other) + 1


def test_a_figure_drawn_before_is_copied_bit_for_bit_and_a_fallback_one_is_not_kept(tmp_path, monkeypatch):
    """render_shapes keeps a pyvista figure in the cache folder and, asked for it again, writes the same bytes
    without drawing (pyvista broken by then); a figure drawn by the matplotlib fallback is not kept."""
    import bearingshaft.render as render

    monkeypatch.setenv("BEARINGSHAFT_CACHE", str(tmp_path / "cache"))
    fe, shapes = _two_cell_model()
    drawn = []

    def fake_images(mesh, panels):  # stands in for pyvista: a flat image per panel, counted
        drawn.append(len(panels))
        return [np.full((20, 30, 3), 40 * i, np.uint8) for i in range(len(panels))]

    monkeypatch.setattr(render, "_pyvista_images", fake_images)
    assert render.render_shapes(fe, shapes, tmp_path / "a.png") == "pyvista" and drawn == [2]
    assert len(list((tmp_path / "cache").glob("shapes-*.png"))) == 1

    def broken(mesh, panels):
        raise RuntimeError("no OpenGL")

    monkeypatch.setattr(render, "_pyvista_images", broken)
    assert render.render_shapes(fe, shapes, tmp_path / "b.png") == "pyvista"
    assert (tmp_path / "b.png").read_bytes() == (tmp_path / "a.png").read_bytes()
    used = render.render_shapes(fe, shapes[:1], tmp_path / "c.png")  # another figure: drawn, by the fallback
    assert used.startswith("matplotlib (pyvista failed") and (tmp_path / "c.png").stat().st_size > 0
    assert len(list((tmp_path / "cache").glob("shapes-*.png"))) == 1
