"""The estimator's state vector: which entry is what, for every configuration.

The estimator builds one :class:`StateLayout` per model and everything downstream (the
pipeline, the recorded estimates, the dashboard, the tests' truth) reads states through it,
so a layout is defined here once and never re-derived from a length.

Entries, in order (absent groups take no room)::

    d, h, ḋ, ḣ        position and velocity of the support D (ζ and η, m and m/s)
    φ                 attitude of the body frame (rad); only with an attitude state
    b_1..b_Γ          amplitudes of the unit deformations (dimensionless)
    r_1..r_R          amplitudes of the residual modes (dimensionless); only when carried
    bξ_1..bξ_Γξ       a biaxial beam's unit deformations in ξ (dimensionless); Γξ = 0: none
    rξ_1..rξ_Rξ       its residual modes in ξ
    v_1..v_Γ          acc: v = ḃ + c·ω_D, the integrated velocity state (1/s)
    vξ_1..vξ_Γξ       acc: the ξ plane's v = ḃξ (a biaxial beam is clamped: no ω)
    vr_1..vr_R        rates ṙ of the residual modes (1/s)
    vrξ_1..vrξ_Rξ     rates of the ξ residual modes
    β_1..β_ν          gyro: biases of the peripheral gyroscopes about z (rad/s)
    βξ_1..βξ_ν        gyro, Γξ > 0: biases of the peripheral gyroscopes about y (ξ plane)
    β_D               bias of the gyroscope at D (rad/s); only with an attitude state

A support that fixes the attitude (the clamped beam of the paper's Section 3.5, φ ≡ 0) has no
φ and no β_D: β_D only ever enters through ω = ω_D − β_D, the attitude's rate.

Residual modes are the R eigenmodes after the Γ unit deformations, carried (with their FE
dynamics) so that a driven mode the estimator does not report cannot alias into b: a clamped
beam's base motion drives every mode. r follows b directly, so b and r form one block of Γ + R
modal amplitudes that the aiding equations see alike; they are not unit deformations, so ``b``
and the mode labels stay Γ. A biaxial beam's ξ block (bξ, rξ) follows the ζ block directly: a
strain gauge at an angle sees both planes, so its Jacobian row covers one contiguous range. With
Γξ = 0 (a planar beam) the layout is exactly the planar one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import numpy as np

__all__ = ["Peripheral", "StateIndex", "StateLayout"]

Peripheral = Literal["gyro", "acc"]


class StateIndex(NamedTuple):
    """Start indices of a layout's groups as plain integers (−1: the group is absent), for
    compiled code that cannot hold a Python object. Group lengths: b and v have Γ entries, the
    peripheral biases ν; the R residual amplitudes follow b directly (from b + Γ) and their rates
    start at ``residual_rate``. The ξ plane's groups (``b_xi``: Γξ + Rξ amplitudes, ``v_xi``: Γξ,
    ``residual_rate_xi``: Rξ, ``peripheral_bias_xi``: ν) are −1 for a planar layout."""

    size: int
    d: int
    h: int
    d_rate: int
    h_rate: int
    phi: int
    b: int
    v: int
    peripheral_bias: int
    bias_d: int
    gamma: int
    nu: int
    residual: int = 0
    residual_rate: int = -1
    b_xi: int = -1
    v_xi: int = -1
    residual_rate_xi: int = -1
    peripheral_bias_xi: int = -1
    gamma_xi: int = 0
    residual_xi: int = 0


@dataclass(frozen=True)
class StateLayout:
    """Named positions in the state vector of one estimator configuration.

    Parameters
    ----------
    peripheral : "gyro" or "acc", the kinematic model of the peripheral IMUs.
    gamma : Γ, the number of unit deformations (>= 1).
    nu : ν, the number of peripheral IMUs (>= 0).
    attitude : whether φ (and with it β_D) is a state; False for a support that fixes φ ≡ 0.
    imu_names : names of the ν peripheral IMUs (state names of their biases); default "1".."ν".
    residual : R, the number of residual modes carried after b (>= 0; default 0).
    gamma_xi : Γξ, a biaxial beam's unit deformations in ξ (>= 0; default 0: a planar layout).
    residual_xi : Rξ, residual modes carried in ξ (>= 0, only with Γξ > 0).

    Raises
    ------
    ValueError
        For an unknown configuration, Γ < 1, ν < 0, R < 0, Γξ < 0, Rξ < 0 (or Rξ > 0 with Γξ = 0), an
        attitude state with Γξ > 0 (a biaxial beam is clamped) or names that do not match ν.
    """

    peripheral: Peripheral
    gamma: int
    nu: int
    attitude: bool = True
    imu_names: tuple[str, ...] = ()
    residual: int = 0
    gamma_xi: int = 0
    residual_xi: int = 0
    _index: StateIndex = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.peripheral not in ("gyro", "acc"):
            raise ValueError(f"peripheral={self.peripheral!r} must be 'gyro' or 'acc'")
        for name in ("gamma", "nu", "residual", "gamma_xi", "residual_xi"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{name}={value!r} must be an integer")
        if self.gamma < 1:
            raise ValueError(f"gamma={self.gamma} must be >= 1 (at least one unit deformation)")
        if self.nu < 0:
            raise ValueError(f"nu={self.nu} must be >= 0")
        if self.residual < 0:
            raise ValueError(f"residual={self.residual} must be >= 0")
        if not isinstance(self.attitude, bool):
            raise ValueError(f"attitude={self.attitude!r} must be True or False")
        if self.gamma_xi < 0 or self.residual_xi < 0:
            raise ValueError(f"gamma_xi={self.gamma_xi} and residual_xi={self.residual_xi} must be >= 0")
        if self.residual_xi and not self.gamma_xi:
            raise ValueError(f"residual_xi={self.residual_xi} needs gamma_xi >= 1 (residual modes follow the ξ unit deformations)")
        if self.gamma_xi and self.attitude:
            raise ValueError(f"gamma_xi={self.gamma_xi} with an attitude state: a beam that bends in ξ is clamped (φ ≡ 0)")
        names = tuple(str(n) for n in self.imu_names) or tuple(str(j + 1) for j in range(self.nu))
        if len(names) != self.nu:
            raise ValueError(f"imu_names has {len(names)} names for nu={self.nu} peripheral IMUs")
        object.__setattr__(self, "gamma", int(self.gamma))
        object.__setattr__(self, "nu", int(self.nu))
        object.__setattr__(self, "residual", int(self.residual))
        object.__setattr__(self, "gamma_xi", int(self.gamma_xi))
        object.__setattr__(self, "residual_xi", int(self.residual_xi))
        object.__setattr__(self, "imu_names", names)
        xi = self.gamma_xi > 0
        i = 4
        phi = -1
        if self.attitude:
            phi, i = i, i + 1
        b, i = i, i + self.gamma + self.residual
        b_xi = v = v_xi = peripheral_bias = peripheral_bias_xi = residual_rate = residual_rate_xi = -1
        if xi:
            b_xi, i = i, i + self.gamma_xi + self.residual_xi
        if self.peripheral == "acc":
            v, i = i, i + self.gamma
            if xi:
                v_xi, i = i, i + self.gamma_xi
        if self.residual:
            residual_rate, i = i, i + self.residual
        if self.residual_xi:
            residual_rate_xi, i = i, i + self.residual_xi
        if self.peripheral == "gyro":
            peripheral_bias, i = i, i + self.nu
            if xi:
                peripheral_bias_xi, i = i, i + self.nu
        bias_d = -1
        if self.attitude:
            bias_d, i = i, i + 1
        object.__setattr__(self, "_index", StateIndex(i, 0, 1, 2, 3, phi, b, v, peripheral_bias, bias_d, self.gamma, self.nu,
                                                        self.residual, residual_rate, b_xi, v_xi, residual_rate_xi,
                                                        peripheral_bias_xi, self.gamma_xi, self.residual_xi))

    # -- sizes and positions ----------------------------------------------------------------

    @property
    def index(self) -> StateIndex:
        """The start indices as a tuple of integers (for compiled code)."""
        return self._index

    @property
    def size(self) -> int:
        return self._index.size

    @property
    def d(self) -> int:
        return self._index.d

    @property
    def h(self) -> int:
        return self._index.h

    @property
    def d_rate(self) -> int:
        return self._index.d_rate

    @property
    def h_rate(self) -> int:
        return self._index.h_rate

    @property
    def phi(self) -> int | None:
        """Index of φ, None without an attitude state."""
        return None if self._index.phi < 0 else self._index.phi

    @property
    def b(self) -> slice:
        return slice(self._index.b, self._index.b + self.gamma)

    @property
    def residual_modes(self) -> slice:
        """The residual modes' amplitudes r (R entries, right after b; empty for R = 0)."""
        start = self._index.b + self.gamma
        return slice(start, start + self.residual)

    @property
    def residual_rates(self) -> slice:
        """The residual modes' rates ṙ (R entries; empty for R = 0)."""
        start = self._index.residual_rate
        return slice(0, 0) if start < 0 else slice(start, start + self.residual)

    @property
    def modal(self) -> slice:
        """b and r together: every modal amplitude the estimator carries (Γ + R)."""
        return slice(self._index.b, self._index.b + self.gamma + self.residual)

    @property
    def b_xi(self) -> slice:
        """The ξ plane's unit deformations bξ (Γξ entries; empty for a planar layout)."""
        start = self._index.b_xi
        return slice(0, 0) if start < 0 else slice(start, start + self.gamma_xi)

    @property
    def residual_modes_xi(self) -> slice:
        """The ξ plane's residual modes rξ (Rξ entries, right after bξ; empty without)."""
        start = self._index.b_xi
        return slice(0, 0) if start < 0 else slice(start + self.gamma_xi, start + self.gamma_xi + self.residual_xi)

    @property
    def residual_rates_xi(self) -> slice:
        """The ξ plane's residual rates ṙξ (Rξ entries; empty without)."""
        start = self._index.residual_rate_xi
        return slice(0, 0) if start < 0 else slice(start, start + self.residual_xi)

    @property
    def modal_xi(self) -> slice:
        """bξ and rξ together (Γξ + Rξ; empty for a planar layout)."""
        start = self._index.b_xi
        return slice(0, 0) if start < 0 else slice(start, start + self.gamma_xi + self.residual_xi)

    @property
    def biaxial(self) -> bool:
        """The layout carries the ξ plane (Γξ > 0)."""
        return self.gamma_xi > 0

    @property
    def v_xi(self) -> slice | None:
        """The acc configuration's ξ velocity states (Γξ); None for gyro or a planar layout."""
        i = self._index.v_xi
        return None if i < 0 else slice(i, i + self.gamma_xi)

    @property
    def peripheral_bias_xi(self) -> slice | None:
        """The gyro configuration's peripheral gyro-y biases (ν); None for acc or a planar layout."""
        i = self._index.peripheral_bias_xi
        return None if i < 0 else slice(i, i + self.nu)

    @property
    def v(self) -> slice | None:
        """The acc configuration's velocity states v (Γ); None for gyro (ḃ is an input there)."""
        return None if self._index.v < 0 else slice(self._index.v, self._index.v + self.gamma)

    @property
    def peripheral_bias(self) -> slice | None:
        """The gyro configuration's peripheral gyro biases (ν); None for acc."""
        i = self._index.peripheral_bias
        return None if i < 0 else slice(i, i + self.nu)

    @property
    def bias_d(self) -> int | None:
        """Index of β_D, the gyro bias at D; None without an attitude state."""
        return None if self._index.bias_d < 0 else self._index.bias_d

    @property
    def names(self) -> tuple[str, ...]:
        """State names in order (``d``, ``h``, ``d_rate``, ``h_rate``, ``phi``, ``b1``.., ``r1``..,
        ``bxi1``.., ``rxi1``.., ``v1``.., ``vxi1``.., ``vr1``.., ``vrxi1``.., ``gyro_bias_<imu>``..,
        ``gyro_y_bias_<imu>``.., ``gyro_bias_D``)."""
        out = ["d", "h", "d_rate", "h_rate"]
        if self.attitude:
            out.append("phi")
        out += [f"b{k + 1}" for k in range(self.gamma)]
        out += [f"r{k + 1}" for k in range(self.residual)]
        out += [f"bxi{k + 1}" for k in range(self.gamma_xi)]
        out += [f"rxi{k + 1}" for k in range(self.residual_xi)]
        if self.peripheral == "acc":
            out += [f"v{k + 1}" for k in range(self.gamma)]
            out += [f"vxi{k + 1}" for k in range(self.gamma_xi)]
        out += [f"vr{k + 1}" for k in range(self.residual)]
        out += [f"vrxi{k + 1}" for k in range(self.residual_xi)]
        if self.peripheral == "gyro":
            out += [f"gyro_bias_{name}" for name in self.imu_names]
            if self.gamma_xi:
                out += [f"gyro_y_bias_{name}" for name in self.imu_names]
        if self.attitude:
            out.append("gyro_bias_D")
        return tuple(out)

    def position(self, name: str) -> int:
        """Index of the state called ``name`` (see :attr:`names`)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no state {name!r} in this layout; states: {list(self.names)}") from None

    # -- reading states ---------------------------------------------------------------------

    def check(self, x: object, *, name: str = "x") -> np.ndarray:
        """``x`` as a float array whose last axis is one state vector; ValueError otherwise."""
        try:
            arr = np.asarray(x, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"state vector {name} must be numeric: {exc}") from None
        if arr.ndim not in (1, 2) or arr.shape[-1] != self.size:
            raise ValueError(
                f"state vector {name} has shape {arr.shape}; this layout ({self.peripheral}, Γ={self.gamma}, ν={self.nu}"
                f"{'' if self.attitude else ', no attitude'}{f', {self.residual} residual' if self.residual else ''}{f', Γξ={self.gamma_xi}' if self.gamma_xi else ''}{f', {self.residual_xi} residual ξ' if self.residual_xi else ''}) needs {self.size} entries: {', '.join(self.names)}"
            )
        return arr

    def phi_of(self, x: np.ndarray) -> np.ndarray:
        """φ of state(s) ``x`` (…, n); zeros without an attitude state."""
        x = np.asarray(x)
        i = self.phi
        return np.zeros(x.shape[:-1]) if i is None else x[..., i]

    def b_of(self, x: np.ndarray) -> np.ndarray:
        """b (…, Γ) of state(s) ``x`` (…, n)."""
        return np.asarray(x)[..., self.b]

    def b_xi_of(self, x: np.ndarray) -> np.ndarray:
        """bξ (…, Γξ) of state(s) ``x`` (…, n); (…, 0) for a planar layout."""
        return np.asarray(x)[..., self.b_xi]
