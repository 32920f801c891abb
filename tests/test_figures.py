"""The figures a user reads (issue 24, item 10), each drawn from a small synthetic result: axes named
with units, colour bars where colour carries a number, legends off the data, nothing drawn where
it does not hold (the backbones after the gaps stay open), cells that do not stretch past their
values, and the numbers on the figure checked against closed forms.

Every figure function takes a result and returns a matplotlib figure; these tests never run a solver.
"""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.collections import QuadMesh  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

from bearingshaft import render  # noqa: E402
from bearingshaft.scenes.sweep import Vary  # noqa: E402
from bearingshaft.stages import frc_files, hammer_files  # noqa: E402
from bearingshaft.stages.frc_results import FRCResult  # noqa: E402
from bearingshaft.stages.hammer_results import Record  # noqa: E402
from bearingshaft.sweep import report  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


# -- helpers -----------------------------------------------------------------------------------
def _boxes_overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def _legend_off_the_axes(fig, legend) -> None:
    """The legend's box (pixels) meets no axes' data area."""
    fig.canvas.draw()
    box = legend.get_window_extent()
    for ax in fig.axes:
        if ax.get_visible() and ax.get_label() != "<colorbar>" and ax.has_data():
            assert not _boxes_overlap(box, ax.get_window_extent()), f"legend over the axes {ax.get_title()!r}"


def _colorbar_labels(fig) -> list[str]:
    return [ax.get_ylabel() for ax in fig.axes if ax.get_label() == "<colorbar>"]


# -- the hammer stage: fig10, fig11, levels.png --------------------------------------------------
FS = 4000.0  # Hz, the synthetic records' rate
START_S = 0.01  # s, the blow's start
CONTACTS = ((0.05, 0.06), (0.105, 0.115))  # s, when a gap is closed (the second spans Fig. 10's 110 ms)
GAPS_OPEN_S = 0.4
NAMES = ("hammer", "tip_left_top", "beam_s3:z")


def _record(level_N: float, gain: float = 1.0) -> Record:
    """One second at FS: a 1 ms half-sine blow, a decaying 20 Hz and 300 Hz beam signal (times gain),
    energy 1 J e^{-3 t} after the blow, a "penetration" state > 0 inside CONTACTS."""
    t = np.arange(0.0, 1.0, 1.0 / FS)
    hammer = np.where((t >= START_S) & (t <= START_S + 1e-3), level_N * np.sin(np.pi * (t - START_S) / 1e-3), 0.0)
    beam = gain * np.exp(-2 * t) * (np.sin(2 * np.pi * 20 * t) + 0.5 * np.sin(2 * np.pi * 300 * t)) * (t > START_S)
    cell = 50.0 * np.sin(2 * np.pi * 200 * t) * (t > START_S)
    pen = -np.ones(t.size)
    for a, b in CONTACTS:
        pen[(t >= a) & (t <= b)] = 1.0
    energy = np.where(t > START_S + 1e-3, np.exp(-3 * t), 0.0)
    z = np.zeros(t.size)
    return Record(level_N, t, np.vstack([hammer, cell, beam]), pen[:, None], z[:, None], energy, z, z, {}, 0.0)


def _rig():
    return SimpleNamespace(names=NAMES, location=(0.0, 0.0, 0.0132),
                           system=SimpleNamespace(penetration=lambda x: x))


def _scene():
    sp = SimpleNamespace(dof="beam_s3:z", window_s=0.05, overlap=0.5, fmax_hz=1000.0, db_range=80.0)
    return SimpleNamespace(spectrogram=sp, hammer=SimpleNamespace(start_s=START_S, load_cell="tip_left_top"))


LABELS = {"longitudinal": (6, 10.9, 1.0), "bounce": (9, 19.6, 1.0), "roll": (11, 33.7, 1.0)}
CURVES = {"NNM at 19.6 Hz": (np.geomspace(1e-3, 2.0, 40), np.linspace(20.0, 150.0, 40)),
          "NNM at 731 Hz": (np.array([5.0, 6.0]), np.array([731.0, 731.0]))}  # above the record's energy


def test_fig11_draws_the_backbones_only_while_the_gaps_close():
    rec = _record(500.0)
    fig = hammer_files.draw_fig11(_rig(), rec, _scene(), LABELS, CURVES, GAPS_OPEN_S)
    try:
        ax, az = [a for a in fig.axes if a.get_label() != "<colorbar>"]
        lines = [ln for ln in ax.get_lines() if ln.get_gid() == "backbone"]
        assert len(lines) == 1  # the 731 Hz NNM has no point at the record's energies
        t, f = lines[0].get_data()
        blow_end = START_S + 1e-3
        assert t.max() <= GAPS_OPEN_S + 1e-12 and t.min() >= blow_end - 1.0 / FS
        # f(E(t)) against the curve read by hand: E = e^{-3t} on a log-energy interpolation
        E, fr = CURVES["NNM at 19.6 Hz"]
        expect = np.interp(np.log(np.exp(-3 * t)), np.log(E), fr)
        drawn = np.isfinite(f)  # NaN where the synthetic energy is still 0 (the blow's last samples)
        assert drawn.sum() >= drawn.size - 3 and np.allclose(f[drawn], expect[drawn], rtol=1e-9)
        # the legend names what is not drawn and why, below the panels
        (legend,) = fig.legends
        texts = [x.get_text() for x in legend.get_texts()]
        assert any("731" in x and "not drawn" in x and "above the record's peak energy" in x for x in texts)
        assert any("gaps stay open after 0.4 s" in x for x in texts)
        _legend_off_the_axes(fig, legend)
        # the lower panel: 0-50 Hz, each pseudo-rigid line named
        assert az.get_ylim() == (0.0, 50.0)
        named = [c.get_text() for c in az.texts]
        assert {"longitudinal 10.9 Hz", "bounce 19.6 Hz", "roll 33.7 Hz"} <= set(named)
        assert all("[Hz]" in a.get_ylabel() for a in (ax, az)) and "[s]" in az.get_xlabel()
        assert len(_colorbar_labels(fig)) == 2 and all("dB" in c for c in _colorbar_labels(fig))
    finally:
        plt.close(fig)


def test_fig11_names_every_pseudo_rigid_line_apart():
    """Labels of lines 1 Hz apart are spread to LABEL_GAP of the band; each points at its own line."""
    close = {"a": (0, 10.9, 1.0), "b": (1, 11.9, 1.0), "c": (2, 12.5, 1.0)}
    fig = hammer_files.draw_fig11(_rig(), _record(500.0), _scene(), close, {}, GAPS_OPEN_S)
    try:
        az = [a for a in fig.axes if a.get_label() != "<colorbar>"][1]
        ys = sorted(c.xyann[1] for c in az.texts if c.get_text().endswith("Hz"))
        assert np.all(np.diff(ys) >= hammer_files.LABEL_GAP * 50.0 - 1e-9)
    finally:
        plt.close(fig)


def test_fig10_ends_with_the_gaps_open_and_zooms_on_the_blow():
    rec = _record(500.0)
    closed = rec.x[:, 0] > 0
    t_end = hammer_files.fig10_window(rec.t, closed, START_S)
    # the target START_S + 0.1 s falls inside the second contact: the window runs past its end
    assert t_end >= CONTACTS[1][1] and not closed[np.searchsorted(rec.t, t_end)]
    assert t_end <= CONTACTS[1][1] + hammer_files.FIG10_MARGIN_S + 1.0 / FS
    fig = hammer_files.draw_fig10(_rig(), rec, _scene().hammer)
    try:
        a1, a2 = [a for a in fig.axes if a.get_label() != "<colorbar>" and a.get_ylabel() != "force [N]"]
        assert a2.get_xlim()[1] == pytest.approx(1e3 * t_end)
        (inset,) = a1.child_axes
        lo, hi = inset.get_xlim()
        assert lo < 1e3 * START_S and hi > 1e3 * (START_S + 1e-3) and hi - lo < 3.0  # ms: the blow fills it
        assert "the blow, 1 ms" in inset.get_title()
        assert "[N]" in a1.get_ylabel() and "[N]" in a2.get_ylabel() and "[ms]" in a2.get_xlabel()
    finally:
        plt.close(fig)


def test_fig10_window_without_a_contact_in_progress():
    t = np.arange(0.0, 0.3, 1e-3)
    closed = np.zeros(t.size, bool)
    assert hammer_files.fig10_window(t, closed, 0.01, 0.1, 0.002) == pytest.approx(0.112)
    closed[(t > 0.1125)] = True  # the next contact starts 0.5 ms after the margin would begin: cut before it
    assert hammer_files.fig10_window(t, closed, 0.01, 0.1, 0.002) == pytest.approx(0.112)
    closed[:] = False
    closed[t >= 0.111] = True  # closed from 111 ms to the end: the window stops at the last open sample
    assert hammer_files.fig10_window(t, closed, 0.01, 0.1, 0.002) == pytest.approx(0.110)


def test_levels_share_one_colour_scale():
    """Two blows 100x apart (the beam signal too): one colour bar, one clim, and the weaker panel's
    peak 40 dB (= 20 log10 100) below the stronger's."""
    records = {20.0: _record(20.0, 1.0), 2000.0: _record(2000.0, 100.0)}
    summary = {20.0: {"impacts_total": 0, "gaps_open_after_s": 0.0},
               2000.0: {"impacts_total": 12, "gaps_open_after_s": 0.3}}
    fig = hammer_files.draw_levels(_rig(), records, summary, _scene())
    try:
        meshes = [c for a in fig.axes if a.get_label() != "<colorbar>" for c in a.collections
                  if isinstance(c, QuadMesh)]
        assert len(meshes) == 2 and meshes[0].get_clim() == meshes[1].get_clim()
        lo, hi = meshes[0].get_clim()
        assert hi - lo == pytest.approx(80.0 + 40.0)
        peaks = sorted(float(np.max(m.get_array())) for m in meshes)
        assert peaks[1] - peaks[0] == pytest.approx(40.0, abs=1e-6)
        (label,) = _colorbar_labels(fig)
        assert "one scale for every panel" in label and "dB" in label
        titles = [a.get_title() for a in fig.axes]
        assert "20 N: no impact: the gaps never close" in titles
    finally:
        plt.close(fig)


# -- mode shapes ---------------------------------------------------------------------------------
def _bar(length: float = 10.0):
    """A 1 x 1 x length bar of one hexahedron along x, centred on the x axis."""
    y, z = (-0.5, 0.5), (-0.5, 0.5)
    pts = np.array([[x, yy, zz] for x in (0.0, length) for yy in y for zz in z])
    return pts, np.arange(8)[None, :]


def test_drawing_scale_of_a_translation_is_a_fraction_of_the_model():
    pts, cells = _bar()
    u = np.tile([0.0, 3.0, 0.0], (8, 1))
    s = render.drawing_scale(pts, cells, u)
    assert s * 3.0 == pytest.approx(render.SIZE_FRACTION * 10.0, rel=1e-12)  # 8 % of the 10 m bar


def test_drawing_scale_caps_a_rotation():
    """A roll by theta about the bar's axis: u = theta e_x x r; the largest |du| / |dx| over the
    corners is theta, so the cap gives s theta = MAX_GRADIENT (the size rule alone would give 1.13)."""
    pts, cells = _bar()
    theta = 1e-3
    u = theta * np.cross([1.0, 0.0, 0.0], pts)
    s = render.drawing_scale(pts, cells, u)
    assert s * theta == pytest.approx(render.MAX_GRADIENT, rel=1e-12)
    assert render.SIZE_FRACTION * 10.0 / (theta * np.sqrt(0.5)) * theta > render.MAX_GRADIENT  # the cap binds


class _Mesh:
    """Two hexahedra along x: 'beam' (the first) and 'tube' (the second)."""

    def __init__(self):
        pts = [[x, y, z] for x in (0.0, 1.0, 2.0) for y in (0.0, 0.2) for z in (0.0, 0.2)]
        self.points = np.array(pts)
        idx = {tuple(p): i for i, p in enumerate(pts)}

        def hexa(x0, x1):
            return [idx[(x, y, z)] for x, y, z in ((x0, 0, 0), (x1, 0, 0), (x1, 0.2, 0), (x0, 0.2, 0),
                                                   (x0, 0, 0.2), (x1, 0, 0.2), (x1, 0.2, 0.2), (x0, 0.2, 0.2))]

        self.hexes = np.array([hexa(0.0, 1.0), hexa(1.0, 2.0)])
        self.part_names = ("beam", "tube")

    def part_cells(self, part):
        return np.array([self.part_names.index(part)])

    def part_nodes(self, part):
        return np.unique(self.hexes[self.part_cells(part)])


def test_mode_shapes_have_a_colour_bar_and_say_the_scale():
    mesh = _Mesh()
    u = np.zeros((len(mesh.points), 3))
    u[:, 2] = 1.0  # the whole model moves up: a translation
    u[mesh.part_nodes("tube"), 2] = 0.25
    panels = [render.panel(mesh, "bounce  19.6 Hz", u)]
    fig = render.layout(mesh, panels, [np.zeros((10, 16, 3), np.uint8)], 3)
    try:
        assert _colorbar_labels(fig) == [render.COLOUR_LABEL]
        title = fig.axes[0].get_title()
        extent = 2.0  # m, the model's largest side
        assert f"drawn as {1e3 * render.SIZE_FRACTION * extent:.3g} mm" in title
        assert "beam 1.00, tube 0.25" in title
    finally:
        plt.close(fig)


def test_mode_shapes_render_off_screen(tmp_path):
    pytest.importorskip("pyvista")
    mesh = _Mesh()
    n = len(mesh.points)
    fe = SimpleNamespace(mesh=mesh, solid=SimpleNamespace(nodal_dofs=np.arange(3 * n).reshape(n, 3).T))
    u = np.zeros(3 * n)
    u[2::3] = 1.0
    used = render.render_shapes(fe, [("up", u)], tmp_path / "shapes.png")
    assert (tmp_path / "shapes.png").stat().st_size > 0
    assert used == "pyvista" or used.startswith("matplotlib")


# -- sweep plots ---------------------------------------------------------------------------------
@pytest.mark.parametrize("values", [[200.0, 800.0], [20.0, 200.0, 500.0, 1000.0], [100.0, 400.0, 700.0, 1000.0],
                                    [1e-4, 1e-3, 1e-2, 1e-1], [1.0, 2.0, 3.0, 4.0, 5.0]])
def test_grid_cells_do_not_stretch(values):
    """Each cell holds its value and reaches at most half a step past it; a cell of positive values
    never reaches zero; a categorical axis gives every value an equal cell."""
    v = np.array(values)
    scale, edges = report.grid_axis(v)
    assert edges.size == v.size + 1
    if scale == "categorical":
        assert np.allclose(np.diff(edges), 1.0)
        return
    u, e = (np.log(v), np.log(edges)) if scale == "log" else (v, edges)
    step = np.diff(u).min()
    assert np.all(e[:-1] < u) and np.all(u < e[1:])
    assert np.all(np.diff(e) <= report.EVEN_STEPS * step + 1e-12)
    assert edges[0] > 0


def test_grid_axis_of_the_issue():
    """The row of 200 N in a grid of 200 and 800 N: no cell from -100 to 500 N."""
    assert report.grid_axis(np.array([200.0, 800.0]))[0] == "categorical"
    assert report.grid_axis(np.geomspace(5e-5, 1e-3, 15), True)[0] == "log"


def _sweep_rows():
    gaps = np.geomspace(1e-4, 1e-3, 5)
    forces = (200.0, 800.0, 1000.0, 2000.0)  # uneven on either scale: categorical
    return gaps, forces, [{"model.gap": g, "load[0].peak_N": P, "freq_early_hz": 100.0 * P / g * 1e-6,
                           "impacts": int(P / 10), "status": "ok"} for g, P in itertools.product(gaps, forces)]


def test_sweep_maps_name_their_axes_with_units():
    from bearingshaft.scenes import load_scene

    scene = load_scene("sweep-gap-kg")
    gaps, forces, rows = _sweep_rows()
    spec = SimpleNamespace(vary=(Vary("model.gap", tuple(gaps), log=True), Vary("load[0].peak_N", forces)),
                           design="grid")
    labels = (report.key_label(scene, "model.gap"), "peak of the blow, load[0].peak_N [N]")
    assert labels[0] == "radial clearance at each tip, model.gap [m]"
    fig = report.draw_maps(rows, spec, ["freq_early_hz", "impacts"], "t", (None, None), labels)
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == labels[0] and ax.get_xscale() == "log"
        assert ax.get_ylabel().startswith(labels[1]) and "not to scale" in ax.get_ylabel()
        assert [t.get_text() for t in ax.get_yticklabels()] == ["200", "800", "1e+03", "2e+03"]
        assert _colorbar_labels(fig) == ["dominant frequency, first 1/8 of the record [Hz]", "number of impacts"]
        fig.canvas.draw()
        for a in fig.axes:  # no two tick labels of an axis overlap
            for ticks in (a.get_xticklabels(), a.get_yticklabels()):
                boxes = [t.get_window_extent() for t in ticks if t.get_visible() and t.get_text()]
                assert not any(_boxes_overlap(p, q) for p, q in itertools.combinations(boxes, 2))
    finally:
        plt.close(fig)


def test_every_default_metric_has_a_name_and_unit():
    for m in report.DEFAULT_PLOTS:
        label = report.metric_label(m)
        assert label != m.replace("_", " "), m
    assert report.metric_label("gaps_open_after_s") == "time after which the gaps stay open [s]"
    assert report.metric_label("growth_rate_per_s").endswith("[1/s]")


# -- the frc stage -------------------------------------------------------------------------------
class _Branch:
    """An FRC curve of a linear oscillator: amplitude P |H(f)| at two points, stable but for one stretch."""

    def __init__(self, P: float, f: np.ndarray):
        self.freq_hz = f
        self.amplitude_m = np.column_stack([P * _receptance(f), 2 * P * _receptance(f)])
        self.stable = ~((f > 18.0) & (f < 19.0))
        self.segment = np.zeros(f.size, int)
        self.H = 5

    def pieces(self):
        return [np.arange(self.freq_hz.size)]


def _receptance(f: np.ndarray) -> np.ndarray:
    """m/N, |H| of a 1 kg, 20 Hz, 2 % damped oscillator."""
    w, wn = 2 * np.pi * f, 2 * np.pi * 20.0
    return 1.0 / np.abs(wn**2 - w**2 + 2j * 0.02 * wn * w)


def _frc_result() -> FRCResult:
    f = np.geomspace(10.0, 100.0, 200)
    levels = (0.1, 1.0, 10.0)
    fs = np.array([15.0, 20.0, 25.0])
    sweeps = {P: {"up": SimpleNamespace(freq_hz=fs, amplitude_m=np.column_stack([P * _receptance(fs)] * 2),
                                        response=["periodic", "not_settled", "settling"])} for P in levels}
    spec = SimpleNamespace(point="x2", freq_min_hz=10.0, freq_max_hz=100.0, harmonics=5)
    return FRCResult(scene_name="synthetic", spec=spec, names=("x1", "x2"), load_col=1,
                     curves={P: _Branch(P, f) for P in levels}, events={P: np.array([18.0, 19.0]) for P in levels},
                     checks={}, sweeps=sweeps, sweep_hb={}, convergence=[], backbone_curves={},
                     backbones={0: (np.array([20.0, 30.0]), np.array([[1e-3, 2e-3], [2e-3, 4e-3]]))},
                     peaks={}, nearest={})


def test_frc_legend_outside_and_a_colour_per_level():
    fig = frc_files.draw_frc(_frc_result())
    try:
        (legend,) = fig.legends
        _legend_off_the_axes(fig, legend)
        texts = [t.get_text() for t in legend.get_texts()]
        # each level's entry names its level, then how its drawn curve was computed ("P = 1 N: HB H=5")
        assert [t.split(":")[0] for t in texts[:3]] == ["P = 0.1 N", "P = 1 N", "P = 10 N"]
        assert all(":" in t for t in texts[:3]) and legend.get_texts()[0].get_fontsize() >= 8
        ax = fig.axes[0]
        # the filled (not settled) markers carry their level's colour
        filled = [ln for ln in ax.get_lines() if ln.get_marker() == "^" and ln.get_markerfacecolor() != "none"
                  and ln.get_xdata().size]
        assert sorted(to_rgba(ln.get_markerfacecolor()) for ln in filled) == sorted(to_rgba(f"C{i}") for i in range(3))
        assert all("[m]" in a.get_ylabel() and "[Hz]" in a.get_xlabel() for a in fig.axes)
    finally:
        plt.close(fig)


def test_frc_receptance_is_the_response_per_newton():
    """A linear oscillator: every level's curve over P is the closed-form |H(f)| (m/N)."""
    result = _frc_result()
    fig = frc_files.draw_receptance(result)
    try:
        (legend,) = fig.legends
        _legend_off_the_axes(fig, legend)
        ax = fig.axes[0]
        assert ax.get_ylabel() == "max |x1| / P [m/N]"
        solid = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-" and ln.get_marker() in ("None", "")]
        assert len(solid) == 3
        f = result.curves[1.0].freq_hz
        stable = result.curves[1.0].stable
        for ln in solid:
            y = np.asarray(ln.get_ydata(), float)
            assert np.allclose(y[stable], _receptance(f)[stable], rtol=1e-12)
        widths = sorted(ln.get_linewidth() for ln in solid)
        assert widths[0] < widths[1] < widths[2]  # coinciding levels show as nested bands
    finally:
        plt.close(fig)


# -- integrator_speed.png ------------------------------------------------------------------------
def _benchmark():
    spec = importlib.util.spec_from_file_location("integrator_speed", ROOT / "benchmarks" / "integrator_speed.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# alternate(): the explicit rows' kernels measured in one loop, each warmed once and then run once a round in
# turn (issue 28, session 14: two rows of one kernel measured apart differed by 20 %)
def test_alternate_warms_each_then_runs_them_in_turn_and_reports_cpu_medians():
    bench = _benchmark()
    calls = []

    def work(name, n):
        def fn():
            calls.append(name)
            return sum(range(n))  # CPU work, so the CPU times order as the work
        return fn

    res, t = bench.alternate({"short": work("short", 10_000), "long": work("long", 2_000_000)}, 3)
    assert calls == ["short", "long"] + ["short", "long"] * 3  # warm-ups, then rounds in turn
    assert res == {"short": sum(range(10_000)), "long": sum(range(2_000_000))}
    for c in ("short", "long"):
        assert t[c]["repeats"] == 3 and t[c]["min_s"] <= t[c]["median_s"] <= t[c]["max_s"]
        assert t[c]["wall_min_s"] <= t[c]["wall_median_s"]
    assert t["long"]["median_s"] > 10 * t["short"]["median_s"]  # CPU time (process_time), the kernels' measure


def test_integrator_speed_names_its_baseline_and_keeps_the_legends_off_the_points():
    bench = _benchmark()
    base = bench.BASELINE.format("fc521a5")
    heads = [{"what": "exact ringdown, discrete-impulse, 2 s", "ours_s": "0.02", "baseline": base,
              "baseline_s": "0.1", "ratio": "5", "error": ""},
             {"what": "exact vs DOP853 restarted at every crossing, discrete-impulse 0.2 s", "ours_s": "0.003",
              "baseline": "", "baseline_s": "1.5", "ratio": "500", "error": "DOP853 1e-7; exact 1e-12"}]
    scans = [{"window_s": "0.2", "rtol": r, "wall_s": w, "error": e, "error_measure": "max-norm error"}
             for r, w, e in (("1e-7", "1.1", "7e-5"), ("1e-10", "1.6", "1.6e-7"))]
    fig = bench.draw(heads, scans)
    try:
        texts = [t.get_text() for a in fig.axes for t in a.get_legend().get_texts()]
        assert "the previous release's kernels (commit fc521a5), same process" in texts
        assert not any("issue 14" in t for t in texts)
        for a in fig.axes:
            fig.canvas.draw()
            assert not _boxes_overlap(a.get_legend().get_window_extent(), a.get_window_extent())
    finally:
        plt.close(fig)


def test_friction_panel_names_the_motions_it_does_not_draw():
    """friction.png leaves out a run whose modal energy never reaches the panel (below ENERGY_FLOOR of the
    peak) and says so in the title; a mode hidden in both runs is named once."""
    hidden = [("lateral", "with"), ("lateral", "without"), ("yaw", "with"), ("yaw", "without"),
              ("roll", "without")]
    assert hammer_files._hidden_text(hidden) == "lateral, yaw (both runs); roll (without friction)"
    assert hammer_files._hidden_text([("roll", "with")]) == "roll (with friction)"
