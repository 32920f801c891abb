"""Modal parameters from FRFs: poly-reference least-squares complex frequency (pLSCF, "PolyMAX"),
its stabilization diagram, and mode shapes by least-squares frequency-domain fitting (LSFD).

**pLSCF** (Guillaume, Verboven, Vanlanduit, Van der Auweraer, Peeters, "A poly-reference
implementation of the least-squares complex frequency-domain estimator", IMAC XXI, 2003;
Peeters, Van der Auweraer, Guillaume, Leuridan, "The PolyMAX frequency-domain method: a new
standard for modal parameter estimation?", Shock and Vibration 11, 2004). The FRFs of output o
to the n_i references, a row H_o(f) (1 x n_i), are modelled by a right matrix fraction in
z = exp(i 2 pi f dt) of order p,

    H_o(f) = N_o(z) D(z)^-1,   N_o(z) = sum_j z^j beta_oj (1 x n_i),   D(z) = sum_j z^j alpha_j (n_i x n_i),

with dt = 1 / (2 f_max), f_max the top of the band (the band is mapped onto the upper half of
the unit circle). The equation error E_o = w_o (N_o - H_o D), linear in the real coefficients,
gives per output the normal-equation blocks R_o = Re(X_o^H X_o), S_o = Re(X_o^H Y_o),
T_o = Re(Y_o^H Y_o) (X_o the rows w_o z^j, Y_o the rows -w_o z^j H_o); the numerators are
eliminated,

    M = sum_o (T_o - S_o^T R_o^-1 S_o),   M alpha = 0,

and the constraint alpha_p = I gives alpha_0..p-1 = -M_aa^-1 M_ab. The poles are the
eigenvalues mu of the block companion matrix of D(z)^T (its last block row
-alpha_0^T .. -alpha_{p-1}^T), lambda = ln(mu) / dt, and the first block of each
eigenvector is the pole's participation vector l (l^T D(mu) = 0). Real coefficients give
conjugate pairs; a pole is kept if Im(lambda) > 0, Re(lambda) < 0 and its frequency lies in the
band. On data that is exactly rational in z of order p (a sampled sum of exponentials) the
fit is exact and the poles are recovered to round-off (tests/test_frf.py).

**Stabilization**: a pole of order p is stable in frequency, damping and vector against the
nearest pole of the previous order (relative change below ``tol_freq``, ``tol_damping``, and
1 - MAC of the participation vectors below ``tol_vector`` when there are several references).
:func:`select_modes` groups the poles stable in all three by frequency and keeps the groups
seen at enough orders, each represented by its median pole.

**LSFD**: with the poles and participation vectors fixed, the residues (mode shapes) psi_or
and real lower and upper residuals of every output follow from one linear least-squares fit
of the receptance-type FRFs,

    H_oi(s) = sum_r [psi_or l_ir / (s - lambda_r) + conj(psi_or l_ir) / (s - conj(lambda_r))]
              + UR_oi + LR_oi / s^2,   s = i 2 pi f.

Acceleration FRFs are divided by s^2 first (:func:`receptance`), so that the pole-residue
form has no polynomial part; the shapes are the same.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TOL_FREQ = 0.01  # relative frequency change of a stable pole between orders (1 %, PolyMAX's usual)
TOL_DAMPING = 0.05  # relative damping change (5 %)
TOL_VECTOR = 0.02  # 1 - MAC of the participation vectors (2 %)
ZETA_FLOOR = 1e-3  # damping ratio below which the damping criterion is absolute: |d zeta| < tol * floor


@dataclass(frozen=True, eq=False)
class OrderPoles:
    """The physical poles of one model order (Im > 0, Re < 0, in the band) and their stability.

    Attributes
    ----------
    order : int
        p, the model order.
    lam : (k,) ndarray of complex
        rad/s, the poles, by increasing frequency.
    participation : (n_ref, k) ndarray of complex
        Participation vectors, unit norm.
    stable_freq, stable_damping, stable_vector : (k,) ndarray of bool
        Against the previous order (all False at the first order).
    """

    order: int
    lam: np.ndarray
    participation: np.ndarray
    stable_freq: np.ndarray
    stable_damping: np.ndarray
    stable_vector: np.ndarray

    @property
    def freq_hz(self) -> np.ndarray:
        """Hz, |lambda| / 2 pi (the undamped natural frequency)."""
        return np.abs(self.lam) / (2 * np.pi)

    @property
    def zeta(self) -> np.ndarray:
        """Damping ratios, -Re(lambda) / |lambda|."""
        return -self.lam.real / np.abs(self.lam)

    @property
    def stable(self) -> np.ndarray:
        return self.stable_freq & self.stable_damping & self.stable_vector


def receptance(freq_hz: np.ndarray, H: np.ndarray, quantity: str) -> np.ndarray:
    """FRFs of displacement from FRFs of ``quantity`` (acceleration / s^2, velocity / s), s = i 2 pi f.

    Parameters
    ----------
    freq_hz : (nf,) array_like of float
        Hz, > 0.
    H : (..., nf) array_like of complex
        The FRFs.
    quantity : {'displacement', 'velocity', 'acceleration'}
        What H's numerator is.

    Returns
    -------
    (..., nf) ndarray of complex
    """
    s = 2j * np.pi * np.asarray(freq_hz, float)
    k = {"displacement": 0, "velocity": 1, "acceleration": 2}[quantity]
    return np.asarray(H, complex) / s**k


def _normal_blocks(freq_hz: np.ndarray, H: np.ndarray, p_max: int, dt: float):
    """R (p+1, p+1) shared by the outputs (unit weight), S_o and T_o of every output at order p_max."""
    z = np.exp(2j * np.pi * freq_hz * dt)
    Om = z[:, None] ** np.arange(p_max + 1)[None, :]  # (nf, p+1)
    n_out, n_ref, nf = H.shape
    w = 1.0 / np.sqrt(np.mean(np.abs(H) ** 2, axis=(1, 2)))  # every output counts alike
    Hw = H * w[:, None, None]
    R = np.real(Om.conj().T @ Om)  # (p+1, p+1)
    # Y_o[f, j n_ref + i] = -Om[f, j] Hw[o, i, f]
    S = -np.real(np.einsum("fj,fk,oif->ojki", Om.conj(), Om, Hw)).reshape(n_out, p_max + 1, (p_max + 1) * n_ref)
    G = np.einsum("oif,olf->oilf", Hw.conj(), Hw)  # (n_out, n_ref, n_ref, nf)
    T = np.real(np.einsum("fj,fk,oilf->ojikl", Om.conj(), Om, G))
    T = T.reshape(n_out, (p_max + 1) * n_ref, (p_max + 1) * n_ref)
    return R, S, T


def _poles_of_order(R, S, T, p: int, n_ref: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """All poles (rad/s) and participation vectors of order p from the order-p_max blocks."""
    q = (p + 1) * n_ref
    Rp, Sp, Tp = R[: p + 1, : p + 1], S[:, : p + 1, :q], T[:, :q, :q]
    M = Tp.sum(axis=0) - np.einsum("oja,ojb->ab", Sp, np.linalg.solve(Rp[None], Sp))
    M = 0.5 * (M + M.T)
    a = p * n_ref
    alpha = np.vstack([-np.linalg.solve(M[:a, :a], M[:a, a:]), np.eye(n_ref)])  # ((p+1) n_ref, n_ref)
    A = np.zeros((a, a))
    A[: a - n_ref, n_ref:] = np.eye(a - n_ref)
    for j in range(p):
        A[a - n_ref:, j * n_ref:(j + 1) * n_ref] = -alpha[j * n_ref:(j + 1) * n_ref].T
    mu, V = np.linalg.eig(A)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.log(mu.astype(complex)) / dt
    L = V[:n_ref]
    return lam, L / np.maximum(np.linalg.norm(L, axis=0), 1e-300)


def lscf(freq_hz, H, orders, f_max_hz: float | None = None, tol_freq: float = TOL_FREQ,
         tol_damping: float = TOL_DAMPING, tol_vector: float = TOL_VECTOR) -> list[OrderPoles]:
    """Poles of every model order in ``orders`` by pLSCF, with their stability flags.

    Parameters
    ----------
    freq_hz : (nf,) array_like of float
        Hz, the band's frequency lines (> 0).
    H : (n_out, n_ref, nf) or (n_out, nf) array_like of complex
        The FRFs in the band (receptance-type preferred: :func:`receptance`).
    orders : iterable of int
        Model orders p >= 1, in increasing order.
    f_max_hz : float, optional
        Hz, dt = 1 / (2 f_max) (default: the top of the band).
    tol_freq, tol_damping, tol_vector : float
        Stability tolerances (see the module's docstring).

    Returns
    -------
    list of OrderPoles, one per order

    Raises
    ------
    ValueError
        Shapes that do not agree, non-positive frequencies, or orders not increasing from >= 1.
    """
    f = np.asarray(freq_hz, float)
    H = np.asarray(H, complex)
    if H.ndim == 2:
        H = H[:, None, :]
    orders = [int(p) for p in orders]
    if H.ndim != 3 or H.shape[2] != f.size or f.size < 2 or not np.all(f > 0):
        raise ValueError(f"need freq_hz (nf,) > 0 and H (n_out, n_ref, nf), got {f.shape} and {H.shape}")
    if not orders or orders[0] < 1 or any(b <= a for a, b in zip(orders, orders[1:], strict=False)):
        raise ValueError(f"orders must increase from >= 1, got {orders}")
    f_max = float(f_max_hz or f.max())
    dt = 1.0 / (2.0 * f_max)
    n_ref = H.shape[1]
    R, S, T = _normal_blocks(f, H, orders[-1], dt)
    out: list[OrderPoles] = []
    prev = None
    for p in orders:
        lam, L = _poles_of_order(R, S, T, p, n_ref, dt)
        fr = np.abs(lam) / (2 * np.pi)
        keep = np.isfinite(lam) & (lam.imag > 0) & (lam.real < 0) & (fr >= f.min()) & (fr <= f.max())
        idx = np.flatnonzero(keep)[np.argsort(fr[keep])]
        lam, L = lam[idx], L[:, idx]
        sf, sd, sv = (np.zeros(lam.size, bool) for _ in range(3))
        if prev is not None and prev.lam.size:
            fz, zz = np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)
            for k in range(lam.size):
                j = int(np.argmin(np.abs(prev.freq_hz - fz[k])))
                sf[k] = abs(prev.freq_hz[j] - fz[k]) < tol_freq * fz[k]
                sd[k] = abs(prev.zeta[j] - zz[k]) < tol_damping * max(prev.zeta[j], ZETA_FLOOR)
                m = abs(np.vdot(prev.participation[:, j], L[:, k])) ** 2
                sv[k] = n_ref == 1 or 1.0 - m < tol_vector
        prev = OrderPoles(p, lam, L, sf, sd, sv)
        out.append(prev)
    return out


@dataclass(frozen=True, eq=False)
class SelectedModes:
    """The physical modes picked from a stabilization diagram.

    Attributes
    ----------
    lam : (m,) ndarray of complex
        rad/s, one pole per mode (the median of its group), by increasing frequency.
    participation : (n_ref, m) ndarray of complex
        Their participation vectors.
    n_orders : (m,) ndarray of int
        Orders at which each mode was stable.
    spread_hz : (m,) ndarray of float
        Hz, range of the group's frequencies.
    """

    lam: np.ndarray
    participation: np.ndarray
    n_orders: np.ndarray
    spread_hz: np.ndarray

    @property
    def freq_hz(self) -> np.ndarray:
        return np.abs(self.lam) / (2 * np.pi)

    @property
    def zeta(self) -> np.ndarray:
        return -self.lam.real / np.abs(self.lam)


def select_modes(diagram: list[OrderPoles], min_share: float = 0.3, tol_freq: float = TOL_FREQ / 2,
                 near_hz: tuple[float, ...] = ()) -> SelectedModes:
    """Group the fully stable poles of a diagram by frequency and keep the persistent groups.

    Poles stable in frequency, damping and vector are sorted by frequency and grouped while
    each is within ``tol_freq`` of its group's running median; a group seen at no fewer than
    ``min_share`` of the orders is a mode, represented by the median of its real and imaginary
    parts (and the participation vector of the member nearest to it). With ``near_hz``, the
    mode nearest each of those frequencies is kept instead (as a test engineer picks them).

    Parameters
    ----------
    diagram : list of OrderPoles
        From :func:`lscf`.
    min_share : float
        Share of the orders at which a group must be stable.
    tol_freq : float
        Relative width of a group.
    near_hz : tuple of float
        Hz, pick the group nearest each (default: every persistent group).

    Returns
    -------
    SelectedModes
    """
    rows = [(o.order, lam, o.participation[:, k]) for o in diagram for k, lam in enumerate(o.lam) if o.stable[k]]
    n_ref = diagram[0].participation.shape[0]
    rows.sort(key=lambda r: abs(r[1]))
    groups: list[list] = []
    for r in rows:
        f = abs(r[1])
        if groups and abs(f - np.median([abs(g[1]) for g in groups[-1]])) < tol_freq * f:
            groups[-1].append(r)
        else:
            groups.append([r])
    n_orders = len(diagram)
    sizes = np.array([len({g[0] for g in grp}) for grp in groups], int)
    centres = np.array([np.median([abs(g[1]) for g in grp]) / (2 * np.pi) for grp in groups])
    if near_hz:
        chosen = sorted({int(np.argmin(np.abs(centres - f))) for f in near_hz}) if groups else []
    else:
        chosen = [i for i, s in enumerate(sizes) if s >= min_share * n_orders]
    lam, L, n, spread = [], [], [], []
    for i in chosen:
        grp = groups[i]
        lg = np.array([g[1] for g in grp])
        med = complex(np.median(lg.real), np.median(lg.imag))
        k = int(np.argmin(np.abs(lg - med)))
        lam.append(med)
        L.append(grp[k][2])
        n.append(sizes[i])
        spread.append((np.abs(lg).max() - np.abs(lg).min()) / (2 * np.pi))
    order = np.argsort(np.abs(lam)) if lam else np.zeros(0, int)
    return SelectedModes(lam=np.array(lam, complex)[order],
                         participation=(np.array(L).T if L else np.zeros((n_ref, 0), complex))[:, order],
                         n_orders=np.array(n, int)[order], spread_hz=np.array(spread)[order])


@dataclass(frozen=True, eq=False)
class LSFDFit:
    """Mode shapes (residues) and residuals fitted with fixed poles.

    Attributes
    ----------
    psi : (n_out, m) ndarray of complex
        psi_or: the residue of output o in mode r is psi_or l_ir for reference i.
    upper, lower : (n_out, n_ref) ndarray of float
        Upper (constant) and lower (1/s^2) residuals.
    synthesized : (n_out, n_ref, nf) ndarray of complex
        The fitted FRFs.
    correlation : (n_out,) ndarray of float
        FRF correlation of data and fit per output, |sum conj(H) H_fit|^2 / (sum|H|^2 sum|H_fit|^2).
    """

    psi: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    synthesized: np.ndarray
    correlation: np.ndarray


def lsfd(freq_hz, H, lam, participation) -> LSFDFit:
    """Residues and residuals of every output with the poles ``lam`` and participation fixed.

    Parameters
    ----------
    freq_hz : (nf,) array_like of float
        Hz, > 0.
    H : (n_out, n_ref, nf) or (n_out, nf) array_like of complex
        Receptance-type FRFs (:func:`receptance`).
    lam : (m,) array_like of complex
        rad/s, the poles (Im > 0).
    participation : (n_ref, m) array_like of complex
        Their participation vectors.

    Returns
    -------
    LSFDFit
    """
    f = np.asarray(freq_hz, float)
    H = np.asarray(H, complex)
    if H.ndim == 2:
        H = H[:, None, :]
    lam = np.asarray(lam, complex)
    L = np.asarray(participation, complex).reshape(H.shape[1], lam.size)
    n_out, n_ref, nf = H.shape
    m = lam.size
    s = 2j * np.pi * f
    cols = []
    for r in range(m):  # Re(psi_r) and Im(psi_r): (n_ref, nf) complex columns
        a = L[:, r, None] / (s[None] - lam[r])
        b = np.conj(L[:, r, None]) / (s[None] - np.conj(lam[r]))
        cols += [a + b, 1j * (a - b)]
    for i in range(n_ref):
        e = np.zeros((n_ref, nf), complex)
        e[i] = 1.0
        cols += [e, e / s[None] ** 2]
    A = np.stack([c.ravel() for c in cols], axis=1)  # (n_ref nf, 2m + 2 n_ref)
    A_real = np.vstack([A.real, A.imag])
    scale = np.linalg.norm(A_real, axis=0)
    B = H.reshape(n_out, -1).T
    B_real = np.vstack([B.real, B.imag])
    x = np.linalg.lstsq(A_real / scale, B_real, rcond=None)[0] / scale[:, None]  # (2m + 2 n_ref, n_out)
    psi = (x[0:2 * m:2] + 1j * x[1:2 * m:2]).T
    res = x[2 * m:].reshape(n_ref, 2, n_out)
    fit = (A @ x).T.reshape(n_out, n_ref, nf)
    num = np.abs(np.sum(np.conj(H) * fit, axis=(1, 2))) ** 2
    den = np.sum(np.abs(H) ** 2, axis=(1, 2)) * np.sum(np.abs(fit) ** 2, axis=(1, 2))
    return LSFDFit(psi=psi, upper=res[:, 0].T, lower=res[:, 1].T, synthesized=fit,
                   correlation=num / np.maximum(den, 1e-300))


def real_shapes(psi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real mode shapes from complex ones, and each one's complexity.

    Each column is turned by the angle theta = arg(sum psi^2) / 2 that makes its real part
    largest; the real part is the shape, scaled to unit largest magnitude with its largest
    component positive. The complexity is |Im| / |psi| after the turn (0 for a normal mode).

    Parameters
    ----------
    psi : (n, m) array_like of complex
        Complex shapes in columns.

    Returns
    -------
    shapes : (n, m) ndarray of float
    complexity : (m,) ndarray of float

    Examples
    --------
    >>> shapes, c = real_shapes(np.array([[1j], [-2j]]))
    >>> shapes.ravel().tolist(), c.round(12).tolist()
    ([-0.5, 1.0], [0.0])
    """
    psi = np.asarray(psi, complex)
    theta = 0.5 * np.angle(np.sum(psi**2, axis=0))
    turned = psi * np.exp(-1j * theta)[None]
    shapes = turned.real.copy()
    big = np.argmax(np.abs(shapes), axis=0)
    peak = shapes[big, np.arange(shapes.shape[1])]
    shapes /= np.where(peak != 0, peak, 1.0)[None]
    complexity = np.linalg.norm(turned.imag, axis=0) / np.maximum(np.linalg.norm(psi, axis=0), 1e-300)
    return shapes, complexity


__all__ = ["OrderPoles", "SelectedModes", "LSFDFit", "lscf", "select_modes", "lsfd", "receptance", "real_shapes",
           "TOL_FREQ", "TOL_DAMPING", "TOL_VECTOR"]
