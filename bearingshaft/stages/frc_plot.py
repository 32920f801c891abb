"""How the frc stage's figures draw a curve of periodic orbits: stable solid, unstable dashed.

Shared by ``frc.png``/``frc_receptance.png`` (:mod:`bearingshaft.stages.frc_files`) and
``response_map.png`` (:mod:`bearingshaft.stages.frc_map_files`); no solver runs here.
"""

from __future__ import annotations

import numpy as np


def draw_curve(ax, curve, c: int, color, lw: float, scale: float = 1.0, label: str | None = None) -> None:
    """Draw output point ``c`` of ``curve`` (an HB branch or a drawn curve: ``pieces()``, ``freq_hz`` [Hz],
    ``amplitude_m`` [m], ``stable``) on ``ax``, each piece in its path order (folds kept): amplitude x
    ``scale`` against frequency, solid where stable, dashed where unstable, the dashed pieces joined to the
    solid ones.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where.
    curve : object
        The curve.
    c : int
        The output point's column.
    color, lw : matplotlib colour, float
        Its colour and the solid line's width (the dashed one is 0.75 of it).
    scale : float
        Amplitude factor (1 / P for a receptance in m/N).
    label : str or None
        Legend text: ``"<label>, stable"`` and ``"<label>, unstable"``; None: no legend entry.
    """
    for idx in curve.pieces():
        a, fr, stb = curve.amplitude_m[idx, c] * scale, curve.freq_hz[idx], curve.stable[idx]
        uns = ~stb
        edge = uns | np.roll(uns, 1) | np.roll(uns, -1)
        ax.plot(fr, np.where(stb, a, np.nan), "-", color=color, lw=lw,
                label=None if label is None else f"{label}, stable")
        ax.plot(fr, np.where(edge, a, np.nan), "--", color=color, lw=0.75 * lw,
                label=None if label is None else f"{label}, unstable")
