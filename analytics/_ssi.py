"""Covariance-driven stochastic subspace identification (SSI-cov).

Output correlations → block Toeplitz matrix → one SVD → the state matrices of every model order
(the multi-order shift solution: one QR of the largest observability matrix serves every order)
→ poles: frequency, damping ratio, mode shape, MPC. Uncertainty from data segments: each
segment's Toeplitz matrix perturbs the observability matrix to first order
(O_j = T_j V_n S_n^{-1/2}), so a jackknife over segments costs one product and one small
eigenproblem per segment, not an SVD (Reynders, Pintelon & De Roeck 2008; Döhler & Mevel 2013).

References: Peeters & De Roeck (1999) "Reference-based stochastic subspace identification for
output-only modal analysis"; Döhler & Mevel (2013) "Efficient multi-order uncertainty computation
for stochastic subspace identification".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

from ._validate import as_signal, check_fs

__all__ = [
    "PoleSet",
    "SsiModel",
    "block_toeplitz",
    "modal_assurance",
    "modal_phase_collinearity",
    "output_correlations",
    "ssi_cov",
    "ssi_poles",
    "segment_correlations",
    "toeplitz_from_data",
]


def _check_int(name: str, value: object, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise ValueError(f"{name}={value!r} must be an integer >= {lo}")
    return int(value)


def _outputs_and_refs(y: object, refs: object | None) -> tuple[np.ndarray, np.ndarray]:
    """y as (N, l) and the references as (N, r) (y itself without refs), both finite."""
    a = as_signal("y", y, min_len=3)
    a = a.reshape(a.shape[0], -1)
    b = a if refs is None else as_signal("refs", refs, min_len=3)
    b = b.reshape(b.shape[0], -1)
    if b.shape[0] != a.shape[0]:
        raise ValueError(f"refs has {b.shape[0]} samples, y has {a.shape[0]}")
    return a, b


def output_correlations(y: object, max_lag: int, *, refs: object | None = None) -> np.ndarray:
    """Unbiased output correlation matrices R_k = E[y(t+k) y_ref(t)ᵀ], k = 0 … max_lag.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
        Outputs, one column per channel (any unit u). The mean is removed.
    max_lag : int
        Largest lag in samples, 1 <= max_lag < N.
    refs : array_like, shape (N,) or (N, r), optional
        Reference channels (default: all outputs).

    Returns
    -------
    R : ndarray, shape (max_lag + 1, l, r)
        R[k] in u², the sum over N - k products divided by N - k (computed with the FFT).

    Raises
    ------
    ValueError
        If y or refs is not a finite numeric array, their lengths differ, or max_lag is out of range.
    """
    a, b = _outputs_and_refs(y, refs)
    max_lag = _check_int("max_lag", max_lag, 1)
    if max_lag >= a.shape[0]:
        raise ValueError(f"{max_lag=} must be below the record length {a.shape[0]}")
    return _correlations(a[None], b[None], max_lag)[0]


def _correlations(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """a (S, N, l), b (S, N, r) → (S, max_lag+1, l, r), unbiased, per segment."""
    n = a.shape[1]
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    nfft = 1 << int(np.ceil(np.log2(n + max_lag)))
    A = np.fft.rfft(a, nfft, axis=1)
    B = np.fft.rfft(b, nfft, axis=1)
    # R_k = Σ_t a(t+k) b(t): the cross-correlation is ifft(A · conj(B))
    r = np.fft.irfft(A[:, :, :, None] * np.conj(B[:, :, None, :]), nfft, axis=1)[:, : max_lag + 1]
    return r / (n - np.arange(max_lag + 1))[None, :, None, None]


def segment_correlations(y: object, max_lag: int, segments: int, *, refs: object | None = None) -> np.ndarray:
    """Output correlations of ``segments`` consecutive, non-overlapping parts of the record.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
        Outputs (any unit u).
    max_lag : int
        Largest lag in samples; must be below N // segments.
    segments : int
        Number of parts (>= 1); each has N // segments samples (a remainder at the end is dropped).
    refs : array_like, shape (N,) or (N, r), optional
        Reference channels (default: all outputs).

    Returns
    -------
    R : ndarray, shape (segments, max_lag + 1, l, r)
        Unbiased correlations of each part (u²). Their mean is the record's estimate; their
        scatter is the estimate's uncertainty.

    Raises
    ------
    ValueError
        If the parts are too short for max_lag, or an argument is invalid.
    """
    a, b = _outputs_and_refs(y, refs)
    segments = _check_int("segments", segments, 1)
    max_lag = _check_int("max_lag", max_lag, 1)
    ns = a.shape[0] // segments
    if ns <= 2 * max_lag:
        raise ValueError(f"{segments=} parts of {ns} samples are too short for {max_lag=} (need more than {2 * max_lag})")
    a = a[: ns * segments].reshape(segments, ns, -1)
    b = b[: ns * segments].reshape(segments, ns, -1)
    return _correlations(a, b, max_lag)


def block_toeplitz(R: object, block_rows: int) -> np.ndarray:
    """The block Toeplitz matrix of output correlations used by SSI-cov.

    Parameters
    ----------
    R : array_like, shape (K, l, r) or (S, K, l, r)
        Correlations R_0 … R_{K-1} (from :func:`output_correlations`), or a stack of them.
    block_rows : int
        i, the number of block rows and columns; needs K >= 2i.

    Returns
    -------
    T : ndarray, shape (i·l, i·r) or (S, i·l, i·r)
        Block (a, b) is R_{i + a - b}: future outputs (rows) against past references (columns).
        Its rank is the model order; T = O · C with O the observability matrix.

    Raises
    ------
    ValueError
        If R has the wrong shape or too few lags for block_rows.
    """
    a = np.asarray(R, dtype=float)
    if a.ndim not in (3, 4):
        raise ValueError(f"R must have shape (K, l, r) or (S, K, l, r), got {a.shape}")
    i = _check_int("block_rows", block_rows, 1)
    k, l, r = a.shape[-3:]
    if k < 2 * i:
        raise ValueError(f"R has {k} lags; block_rows={i} needs {2 * i}")
    # lag index of block (row, col) is i + row - col
    lags = i + np.arange(i)[:, None] - np.arange(i)[None, :]
    blocks = a[..., lags, :, :]  # (..., i, i, l, r)
    return np.swapaxes(blocks, -3, -2).reshape(a.shape[:-3] + (i * l, i * r))


def toeplitz_from_data(y: object, block_rows: int, *, segments: int = 1, refs: object | None = None,
                       weights: object | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The block Toeplitz matrix as a product of data Hankel matrices, T = Y_f Y_pᵀ / N_c.

    Every block sums the same N_c = N - 2i + 1 time steps, so T = O · (X_f Y_pᵀ / N_c) holds
    exactly for any response of the model, a free decay included: the correlation estimate
    divided by N - k (:func:`output_correlations`) assumes stationarity and turns a decay
    into a growth over long lags. For long stationary records the two agree.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
        Outputs (unit u); the mean is removed.
    block_rows : int
        i: future rows y(t+i) … y(t+2i-1), past rows y(t+i-1) … y(t).
    segments : int
        Also return the matrices of this many contiguous groups of the N_c columns [1].
    refs : array_like, shape (N,) or (N, r), optional
        Reference channels for the past rows (default all outputs).
    weights : array_like, shape (N - 2i + 1,), optional
        Non-negative weights of the time steps (columns). Any weighting keeps T = O·(…):
        a taper centres the estimate in time when the system drifts within the record.

    Returns
    -------
    T : ndarray, shape (i·l, i·r)
        The record's matrix (u²): block (a, b) is Σ_t y(t+i+a) y_ref(t+i-1-b)ᵀ / N_c.
    T_segments : ndarray, shape (segments, i·l, i·r)
        The groups' matrices; their mean is T.

    Raises
    ------
    ValueError
        If the record holds fewer than ``segments`` columns per group, or an argument is invalid.
    """
    a, b = _outputs_and_refs(y, refs)
    i = _check_int("block_rows", block_rows, 1)
    segments = _check_int("segments", segments, 1)
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    n, l = a.shape
    r = b.shape[1]
    nc = n - 2 * i + 1
    if nc < 2 * segments:
        raise ValueError(f"y has {n} samples: too few for {block_rows=} and {segments=}")
    # sliding windows: Yf[t] = [y(t+i); …; y(t+2i-1)], Yp[t] = [y(t+i-1); …; y(t)]
    Yf = np.lib.stride_tricks.sliding_window_view(a[i:], i, axis=0)[:nc]  # (nc, l, i)
    Yf = np.swapaxes(Yf, 1, 2).reshape(nc, i * l)
    Yp = np.lib.stride_tricks.sliding_window_view(b[: n - i], i, axis=0)[:nc][:, :, ::-1]
    Yp = np.swapaxes(Yp, 1, 2).reshape(nc, i * r)
    bounds = np.linspace(0, nc, segments + 1).astype(int)
    if weights is None:
        # equal groups (one batched product); the < segments columns left over are dropped
        m = nc // segments
        Ts = np.matmul(np.swapaxes(Yf[: m * segments].reshape(segments, m, i * l), 1, 2), Yp[: m * segments].reshape(segments, m, i * r)) / m
        w = np.full(segments, 1.0 / segments)
    else:
        c = np.asarray(weights, dtype=float)
        if c.shape != (nc,) or np.any(c < 0) or not np.any(c > 0):
            raise ValueError(f"weights must be ({nc},) non-negative with a positive entry, got shape {c.shape}")
        Ts = np.stack([(Yf[s:e] * c[s:e, None]).T @ Yp[s:e] / max(c[s:e].sum(), 1e-300) for s, e in zip(bounds[:-1], bounds[1:])])
        w = np.array([c[s:e].sum() for s, e in zip(bounds[:-1], bounds[1:])]) / c.sum()
    return np.tensordot(w, Ts, axes=1), Ts


@dataclass(frozen=True, eq=False)
class PoleSet:
    """The poles of every model order, flat (one entry per pole, one of each conjugate pair).

    order : (P,) int, model order the pole came from.
    eigenvalue : (P,) complex, continuous-time pole λ = ln(μ)·fs (rad/s), Im λ > 0.
    frequency_hz : (P,) undamped natural frequency |λ|/2π (Hz).
    damping_ratio : (P,) −Re λ / |λ| (dimensionless; 0.01 = 1 %).
    shapes : (P, l) complex, observed mode shapes C·ψ, unit norm, largest component real positive.
    mpc : (P,) modal phase collinearity 0 … 1 (1: a real, classically damped shape).
    """

    order: np.ndarray
    eigenvalue: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    shapes: np.ndarray
    mpc: np.ndarray

    def __len__(self) -> int:
        return int(self.order.size)

    def take(self, index: object) -> "PoleSet":
        """The poles at ``index`` (an index array or boolean mask)."""
        idx = np.asarray(index)
        return PoleSet(self.order[idx], self.eigenvalue[idx], self.frequency_hz[idx], self.damping_ratio[idx], self.shapes[idx], self.mpc[idx])


@dataclass(frozen=True, eq=False)
class SsiModel:
    """An SSI-cov identification over model orders.

    fs_hz : sample rate of the identified data (Hz).
    block_rows : i of the block Toeplitz matrix.
    channels : l, number of outputs.
    singular_values : the leading singular values of the Toeplitz matrix (u²), falling (all of
        them for a small matrix, the first max order + 20 for a large one).
    orders : (n_orders,) model orders evaluated (even).
    poles : every order's poles (:class:`PoleSet`).
    observability : (i·l, max order) U·S^{1/2}, kept to propagate segment perturbations.
    right_vectors : (i·r, max order) V of the SVD.
    """

    fs_hz: float
    block_rows: int
    channels: int
    singular_values: np.ndarray
    orders: np.ndarray
    poles: PoleSet
    observability: np.ndarray
    right_vectors: np.ndarray


def modal_assurance(a: object, b: object) -> np.ndarray:
    """Modal assurance criterion between the rows of a (m, l) and b (k, l), complex or real.

    Returns (m, k) values in [0, 1]: |aᴴb|² / (aᴴa · bᴴb); 1 for shapes equal up to a complex scale.
    """
    x = np.atleast_2d(np.asarray(a))
    y = np.atleast_2d(np.asarray(b))
    if x.shape[-1] != y.shape[-1]:
        raise ValueError(f"shapes have {x.shape[-1]} and {y.shape[-1]} components")
    num = np.abs(np.conj(x) @ y.T) ** 2
    den = np.real(np.sum(np.conj(x) * x, axis=1))[:, None] * np.real(np.sum(np.conj(y) * y, axis=1))[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def modal_phase_collinearity(shapes: object) -> np.ndarray:
    """Modal phase collinearity (Pappa et al. 1993) of the rows of shapes (m, l), complex.

    Returns (m,) in [0, 1]: 1 when all components are in phase (a real mode), 0 for a
    circularly spread shape. A single channel gives 1.
    """
    s = np.atleast_2d(np.asarray(shapes, dtype=complex))
    re, im = s.real, s.imag
    sxx = np.sum(re * re, axis=1)
    syy = np.sum(im * im, axis=1)
    sxy = np.sum(re * im, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        eta = (syy - sxx) / (2 * sxy)
        root = np.sqrt(eta**2 + 1)
        lam1 = (sxx + syy) / 2 + sxy * root
        lam2 = (sxx + syy) / 2 - sxy * root
        out = ((lam1 - lam2) / (lam1 + lam2)) ** 2
    # sxy == 0: the shape is already on an axis pair; collinearity from the two sums
    axis = np.where(sxx + syy > 0, ((sxx - syy) / np.where(sxx + syy > 0, sxx + syy, 1.0)) ** 2, 1.0)
    return np.clip(np.where(np.abs(sxy) > 1e-300, out, axis), 0.0, 1.0)


def _normalise_shapes(phi: np.ndarray) -> np.ndarray:
    """Columns of phi (l, m) → rows (m, l), unit norm, the largest component real positive."""
    s = phi.T
    k = np.argmax(np.abs(s), axis=1)
    ref = s[np.arange(s.shape[0]), k]
    with np.errstate(invalid="ignore", divide="ignore"):
        s = s * (np.abs(ref) / np.where(ref == 0, 1, ref))[:, None]
        return s / np.linalg.norm(s, axis=1, keepdims=True)


def _poles_of(A: np.ndarray, C: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete eigenvalues μ, continuous λ (Im > 0 only) and observed shapes (l, m)."""
    mu, psi = np.linalg.eig(A)
    keep = mu.imag > 0  # one of each complex pair; real eigenvalues are not vibration modes
    mu, psi = mu[keep], psi[:, keep]
    lam = np.log(mu) * fs
    return mu, lam, C @ psi


def _leading_svd(H: np.ndarray, k: int, *, oversample: int = 20, power: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The leading singular triplets of H, at least k of them.

    Only the first k matter to SSI: above a few times k columns a randomized range finder with
    power iterations (Halko, Martinsson & Tropp 2011; a fixed seed, so results repeat) gives
    them at a fraction of a full SVD's cost; its subspace error falls as (σ_{k+p}/σ_n)^(2q+1),
    negligible for the orders that hold the physical modes. Smaller matrices get the full SVD.
    """
    m = min(H.shape)
    if m <= 2 * (k + oversample):
        return linalg.svd(H, full_matrices=False, check_finite=False)
    rng = np.random.default_rng(0)
    Y = H @ rng.standard_normal((H.shape[1], k + oversample))
    for _ in range(power):
        Y, _ = np.linalg.qr(Y)
        Y, _ = np.linalg.qr(H.T @ Y)
        Y = H @ Y
    Q, _ = np.linalg.qr(Y)
    Ub, s, Vt = linalg.svd(Q.T @ H, full_matrices=False, check_finite=False)
    return Q @ Ub, s, Vt


def ssi_poles(T: object, channels: int, fs: float, orders: object) -> SsiModel:
    """Poles of every model order from a block Toeplitz matrix (one SVD, one QR).

    Parameters
    ----------
    T : array_like, shape (i·l, i·r)
        Block Toeplitz matrix (:func:`block_toeplitz`).
    channels : int
        l, outputs per block row.
    fs : float
        Sample rate of the data (Hz).
    orders : sequence of int
        Model orders, each >= 2 and < (i - 1)·l.

    Returns
    -------
    SsiModel
        Poles of every order with frequencies (Hz), damping ratios, shapes and MPC.

    Raises
    ------
    ValueError
        If T does not have i·l rows, or an order is out of range.
    """
    fs = check_fs(fs)
    H = np.asarray(T, dtype=float)
    if H.ndim != 2 or not np.all(np.isfinite(H)):
        raise ValueError(f"T must be a finite 2-D matrix, got shape {H.shape}")
    l = _check_int("channels", channels, 1)
    if H.shape[0] % l:
        raise ValueError(f"T has {H.shape[0]} rows, not a multiple of {channels=}")
    i = H.shape[0] // l
    ords = np.unique(np.asarray(orders, dtype=int))
    if ords.size == 0 or ords[0] < 2 or ords[-1] > min((i - 1) * l, H.shape[1]):
        raise ValueError(f"orders={orders!r} must lie in 2 … {min((i - 1) * l, H.shape[1])} (block_rows={i}, {channels=})")
    nmax = int(ords[-1])
    U, s, Vt = _leading_svd(H, nmax)
    O = U[:, :nmax] * np.sqrt(s[:nmax])
    # shift structure: O_up A = O_down. One QR of the largest O_up gives every order's
    # least-squares solution A_n = R[:n,:n]⁻¹ (Qᵀ O_down)[:n,:n].
    # The leading block of an upper-triangular matrix's inverse is the inverse of its leading block.
    Q, Rq = np.linalg.qr(O[:-l])
    RS = linalg.solve_triangular(Rq, Q.T @ O[l:], check_finite=False)
    Rinv = linalg.solve_triangular(Rq, np.eye(nmax), check_finite=False)
    S = Q.T @ O[l:]
    parts = {k: [] for k in ("order", "lam", "phi")}
    for n in ords:
        A = RS[:n, :n] if n == nmax else Rinv[:n, :n] @ S[:n, :n]
        _, lam, phi = _poles_of(A, O[:l, :n], fs)
        parts["order"].append(np.full(lam.size, n))
        parts["lam"].append(lam)
        parts["phi"].append(phi)
    lam = np.concatenate(parts["lam"])
    shapes = _normalise_shapes(np.concatenate(parts["phi"], axis=1)) if lam.size else np.zeros((0, l), complex)
    wn = np.abs(lam)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = -lam.real / wn
    poles = PoleSet(np.concatenate(parts["order"]).astype(int), lam, wn / (2 * np.pi), zeta, shapes, modal_phase_collinearity(shapes) if lam.size else np.zeros(0))
    return SsiModel(fs, i, l, s, ords, poles, O, Vt[:nmax].T.copy())


def ssi_cov(y: object, fs: float, *, block_rows: int, orders: object, refs: object | None = None) -> SsiModel:
    """Covariance-driven SSI of outputs y over several model orders.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, l)
        Output channels (any consistent unit), sampled at fs.
    fs : float
        Sample rate (Hz).
    block_rows : int
        i; the correlations up to lag 2i - 1 are used (2i/fs seconds of memory).
    orders : sequence of int
        Model orders (state dimensions) to evaluate.
    refs : array_like, shape (N, r), optional
        Reference channels (default all outputs).

    Returns
    -------
    SsiModel
        Poles of every order (see :func:`ssi_poles`).

    Raises
    ------
    ValueError
        If the record is too short for block_rows, or an argument is invalid.
    """
    fs = check_fs(fs)
    a = as_signal("y", y, min_len=3)
    a = a.reshape(a.shape[0], -1)
    i = _check_int("block_rows", block_rows, 2)
    if a.shape[0] <= 4 * i:
        raise ValueError(f"y has {a.shape[0]} samples; {block_rows=} needs more than {4 * i}")
    R = output_correlations(a, 2 * i, refs=refs)
    return ssi_poles(block_toeplitz(R, i), a.shape[1], fs, orders)
