"""Stabilisation diagram and automated pole selection by hierarchical clustering.

A pole is *stable* when the nearest pole of the previous model order agrees in frequency,
damping and shape (MAC). Stable, physically admissible poles are grouped by average-linkage
hierarchical clustering on the distance |Δf|/f + (1 − MAC) (Magalhães, Cunha & Caetano 2009;
Reynders, Houbrechts & De Roeck 2012, whose MAC-and-frequency distance koma also uses). A
cluster is a mode only if it holds poles from a good share of the model orders: a noise pole
or a numerical pole appears at a few orders only, a physical mode at most of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.cluster import hierarchy
from scipy.spatial.distance import squareform

from ._ssi import PoleSet, modal_assurance

__all__ = ["PoleCluster", "StabilisationDiagram", "cluster_poles", "stabilisation_diagram"]


def _check_rel(name: str, value: float, hi: float = 1.0) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) or not (0 < value <= hi):
        raise ValueError(f"{name}={value!r} must be in (0, {hi}]")
    return float(value)


@dataclass(frozen=True, eq=False)
class StabilisationDiagram:
    """Per-pole flags of a stabilisation diagram (arrays of the poles' length P).

    poles : the poles (:class:`analytics.PoleSet`), all orders.
    admissible : (P,) bool, inside the band, damping in (0, max_damping), MPC >= min_mpc.
    stable_frequency, stable_damping, stable_shape : (P,) bool, agreement with the best-matching
        pole of the previous order within freq_rel, damping_rel (relative) and MAC >= mac_min.
    stable : (P,) bool, admissible and all three stable.
    criteria : the thresholds used (freq_rel, damping_rel, mac_min, max_damping, min_mpc, fmin_hz, fmax_hz).
    """

    poles: PoleSet
    admissible: np.ndarray
    stable_frequency: np.ndarray
    stable_damping: np.ndarray
    stable_shape: np.ndarray
    stable: np.ndarray
    criteria: dict


def stabilisation_diagram(
    poles: PoleSet,
    *,
    fmin_hz: float = 0.0,
    fmax_hz: float = np.inf,
    freq_rel: float = 0.01,
    damping_rel: float = 0.2,
    mac_min: float = 0.95,
    max_damping: float = 0.2,
    min_damping: float = 0.0,
    damping_abs: float = 0.002,
    min_mpc: float = 0.0,
) -> StabilisationDiagram:
    """Flag each pole as admissible and as stable against the previous model order.

    Parameters
    ----------
    poles : PoleSet
        Poles of several model orders (:func:`analytics.ssi_poles`).
    fmin_hz, fmax_hz : float
        Band of admissible natural frequencies (Hz).
    freq_rel : float
        Largest relative frequency change to the previous order's matching pole [0.01].
    damping_rel : float
        Largest relative damping change [0.2], or ``damping_abs`` if larger [0.002]: near ζ = 0
        a relative criterion alone would refuse every pole.
    mac_min : float
        Smallest MAC with the matching pole [0.95].
    max_damping, min_damping : float
        Admissible damping ratios are in (min_damping, max_damping) [(0, 0.2)]. A slightly
        negative min_damping admits the apparent growth of a mode in a short window whose
        excitation builds up (a transient is not stationary); numerical poles grow faster.
    min_mpc : float
        Smallest admissible modal phase collinearity [0].

    Returns
    -------
    StabilisationDiagram

    Raises
    ------
    ValueError
        If poles is not a PoleSet or a threshold is out of range.
    """
    if not isinstance(poles, PoleSet):
        raise ValueError(f"poles must be a PoleSet, got {type(poles).__name__}")
    _check_rel("freq_rel", freq_rel)
    _check_rel("damping_rel", damping_rel, hi=10.0)
    _check_rel("mac_min", mac_min)
    _check_rel("max_damping", max_damping)
    if not (-1 < min_damping < max_damping):
        raise ValueError(f"{min_damping=} must be in (-1, {max_damping=})")
    if not (0 <= damping_abs < 1):
        raise ValueError(f"{damping_abs=} must be in [0, 1)")
    if not (0 <= min_mpc <= 1):
        raise ValueError(f"{min_mpc=} must be in [0, 1]")
    if not (0 <= fmin_hz < fmax_hz):
        raise ValueError(f"{fmin_hz=} and {fmax_hz=} must satisfy 0 <= fmin_hz < fmax_hz")
    f, z = poles.frequency_hz, poles.damping_ratio
    with np.errstate(invalid="ignore"):
        admissible = (f >= fmin_hz) & (f <= fmax_hz) & (z > min_damping) & (z < max_damping) & (poles.mpc >= min_mpc)
    P = len(poles)
    sf, sz, ss = (np.zeros(P, bool) for _ in range(3))
    orders = np.unique(poles.order)
    for prev, cur in zip(orders[:-1], orders[1:]):
        ip = np.flatnonzero(poles.order == prev)
        ic = np.flatnonzero(poles.order == cur)
        if ip.size == 0 or ic.size == 0:
            continue
        mac = modal_assurance(poles.shapes[ic], poles.shapes[ip])
        df = np.abs(f[ic][:, None] - f[ip][None, :]) / f[ic][:, None]
        best = np.argmin(df + (1 - mac), axis=1)
        j = ip[best]
        rows = np.arange(ic.size)
        sf[ic] = df[rows, best] <= freq_rel
        with np.errstate(invalid="ignore", divide="ignore"):
            sz[ic] = np.abs(z[ic] - z[j]) <= np.maximum(damping_rel * np.abs(z[j]), damping_abs)
        ss[ic] = mac[rows, best] >= mac_min
    stable = admissible & sf & sz & ss
    crit = dict(freq_rel=freq_rel, damping_rel=damping_rel, damping_abs=damping_abs, mac_min=mac_min, max_damping=max_damping,
                min_damping=min_damping, min_mpc=min_mpc,
                fmin_hz=float(fmin_hz), fmax_hz=float(fmax_hz))
    return StabilisationDiagram(poles, admissible, sf, sz, ss, stable, crit)


@dataclass(frozen=True, eq=False)
class PoleCluster:
    """A group of stable poles taken as one physical mode.

    members : (k,) indices into the diagram's poles, at most one per model order.
    representative : index of the medoid pole (least total distance to the others).
    frequency_hz, damping_ratio : the representative's values.
    frequency_spread_hz, damping_spread : standard deviation across the members (model-order scatter).
    orders : number of distinct model orders in the cluster.
    """

    members: np.ndarray
    representative: int
    frequency_hz: float
    damping_ratio: float
    frequency_spread_hz: float
    damping_spread: float
    orders: int


def _distance(poles: PoleSet, idx: np.ndarray) -> np.ndarray:
    f = poles.frequency_hz[idx]
    df = np.abs(f[:, None] - f[None, :]) / np.maximum(f[:, None], f[None, :])
    return df + (1 - modal_assurance(poles.shapes[idx], poles.shapes[idx]))


def cluster_poles(diagram: StabilisationDiagram, *, distance: float = 0.02, min_orders: float = 0.3) -> tuple[PoleCluster, ...]:
    """Group the stable poles of a diagram into modes, lowest frequency first.

    Parameters
    ----------
    diagram : StabilisationDiagram
        From :func:`stabilisation_diagram`.
    distance : float
        Cut-off of the average-linkage dendrogram in |Δf|/f + (1 − MAC) [0.02].
    min_orders : float
        A cluster must hold poles of at least this fraction of the evaluated model orders
        (at least 3 orders) [0.3]; smaller ones are noise or numerical poles.

    Returns
    -------
    tuple of PoleCluster

    Raises
    ------
    ValueError
        If diagram is not a StabilisationDiagram or a threshold is out of range.
    """
    if not isinstance(diagram, StabilisationDiagram):
        raise ValueError(f"diagram must be a StabilisationDiagram, got {type(diagram).__name__}")
    _check_rel("distance", distance)
    _check_rel("min_orders", min_orders)
    poles = diagram.poles
    idx = np.flatnonzero(diagram.admissible & diagram.stable_shape)
    n_orders = np.unique(poles.order).size
    need = max(3, int(np.ceil(min_orders * n_orders)))
    if idx.size < need:
        return ()
    if idx.size == 1:
        labels = np.ones(1, int)
    else:
        D = _distance(poles, idx)
        # 1 − MAC of two identical shapes can come out a rounding error below zero, which linkage refuses
        D = np.maximum((D + D.T) / 2, 0.0)
        np.fill_diagonal(D, 0.0)
        labels = hierarchy.fcluster(hierarchy.linkage(squareform(D, checks=False), method="average"), t=distance, criterion="distance")
    out = []
    for lab in np.unique(labels):
        members = idx[labels == lab]
        # one pole per order: the one nearest the cluster's median frequency
        fmed = np.median(poles.frequency_hz[members])
        keep = []
        for o in np.unique(poles.order[members]):
            m = members[poles.order[members] == o]
            keep.append(m[np.argmin(np.abs(poles.frequency_hz[m] - fmed))])
        members = np.array(keep)
        if members.size < need:
            continue
        D = _distance(poles, members)
        rep = int(members[np.argmin(D.sum(axis=1))])
        f = poles.frequency_hz[members]
        z = poles.damping_ratio[members]
        out.append(PoleCluster(members, rep, float(poles.frequency_hz[rep]), float(poles.damping_ratio[rep]),
                               float(np.std(f, ddof=1)), float(np.std(z, ddof=1)), int(members.size)))
    out.sort(key=lambda c: c.frequency_hz)
    return tuple(out)
