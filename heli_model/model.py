"""The 13-state hover model of a small unmanned helicopter (paper section 2.1, eq. 4).

The paper flies SERVOHELI-40 on a linear hover model with the Mettler-Tischler-Kanade state
structure; its identified matrices are not public, so the default profile carries the published
Yamaha R-50 hover model of the same class and structure (Mettler, Tischler, Kanade, *System
Identification Modeling of a Model-Scale Helicopter*, CMU-RI-TR-00-03, 1999; values as in
``shared/reference/heli_r50_hover.json``). Users load their own identified parameters with a
profile TOML (see ``profiles/default.toml`` and ``docs/readme/vehicle_model.md``).

State (13) ``[u v w p q r phi theta a b r_fb c d]``: body FRD velocity perturbations (m/s), body
rates (rad/s), roll and pitch (rad), longitudinal and lateral main-rotor flapping ``a``, ``b``
(rad), yaw-damper state ``r_fb``, stabiliser-bar flapping ``c``, ``d`` (rad). Input (4)
``[d_lat d_lon d_ped d_col]``: normalised sticks, ``|delta| <= 1`` is full travel. The model is
a perturbation model about trimmed hover: zero state and zero input is hover at rest.

Equations (continuous time), as in the reference file::

    du/dt = Xu u - g theta + Xa a
    dv/dt = Yv v + g phi + Yb b + Yped d_ped
    dw/dt = Za a + Zb b + Zw w + Zr r + Zcol d_col
    dp/dt = Lu u + Lv v + Lw w + Lb b
    dq/dt = Mu u + Mv v + Mw w + Ma a + Mcol d_col
    dr/dt = Nv v + Np p + Nw w + Nr r + Nrfb r_fb + Nped d_ped + Ncol d_col
    dphi/dt = p ;  dtheta/dt = q
    tau_f da/dt = -tau_f q - a + Ab b + Ac c + Alat d_lat + Alon d_lon
    tau_f db/dt = -tau_f p - b + Ba a + Bd d + Blat d_lat + Blon d_lon
    dr_fb/dt = Kr r + Krfb r_fb
    tau_s dc/dt = -tau_s q - c + Clon d_lon
    tau_s dd/dt = -tau_s p - d + Dlat d_lat

The four flapping and stabiliser-bar rows are written multiplied by their time constant: they
are divided by ``tau_f`` / ``tau_s`` when A and B are formed (the reference's pitfall).

Pure numerics: reading a profile file is the only I/O, in :meth:`HeliModel.from_toml`.
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from heli_common.typed_config import from_dict, load_toml
from heli_model.wind import WindError, WindSettings

STATE_NAMES: tuple[str, ...] = ("u", "v", "w", "p", "q", "r", "phi", "theta", "a", "b", "r_fb", "c", "d")
INPUT_NAMES: tuple[str, ...] = ("d_lat", "d_lon", "d_ped", "d_col")
N_STATES = 13
N_INPUTS = 4

PARAM_NAMES: tuple[str, ...] = (
    "Xu",
    "Xa",
    "Yv",
    "Yb",
    "Lu",
    "Lv",
    "Lb",
    "Lw",
    "Mu",
    "Mv",
    "Ma",
    "Mw",
    "tau_f",
    "Ab",
    "Ac",
    "Ba",
    "Bd",
    "Za",
    "Zb",
    "Zw",
    "Zr",
    "Nv",
    "Np",
    "Nw",
    "Nr",
    "Nrfb",
    "Kr",
    "Krfb",
    "tau_s",
    "Yped",
    "Mcol",
    "Alat",
    "Alon",
    "Blat",
    "Blon",
    "Zcol",
    "Nped",
    "Ncol",
    "Clon",
    "Dlat",
)
POSITIVE_PARAMS: tuple[str, ...] = ("tau_f", "tau_s")

_IDX = {name: i for i, name in enumerate(STATE_NAMES)}
_IN = {name: i for i, name in enumerate(INPUT_NAMES)}


class ModelError(ValueError):
    """A vehicle profile or model parameter is wrong; the message names the key."""


@dataclasses.dataclass(frozen=True)
class _ProfileFile:
    """Top level of a profile TOML (``params`` is checked separately, key by key)."""

    name: str = "unnamed profile"
    source: str = ""
    gravity_m_s2: float = 9.81
    servo_tau_s: float = 0.0
    params: dict | None = None
    wind: WindSettings = dataclasses.field(default_factory=WindSettings)


def assemble_matrices(params: Mapping[str, float], gravity_m_s2: float) -> tuple[np.ndarray, np.ndarray]:
    """Form the continuous-time state and input matrices of the hover model.

    Parameters
    ----------
    params : mapping of str to float
        The 40 stability and control derivatives (SI), keys as :data:`PARAM_NAMES`.
    gravity_m_s2 : float
        Gravitational acceleration, m/s^2.

    Returns
    -------
    A : ndarray, shape (13, 13)
    B : ndarray, shape (13, 4)
    """
    p = params
    g = gravity_m_s2
    A = np.zeros((N_STATES, N_STATES))
    B = np.zeros((N_STATES, N_INPUTS))

    def a(row: str, col: str, value: float) -> None:
        A[_IDX[row], _IDX[col]] += value

    def b(row: str, col: str, value: float) -> None:
        B[_IDX[row], _IN[col]] += value

    # translational dynamics
    a("u", "u", p["Xu"])
    a("u", "theta", -g)
    a("u", "a", p["Xa"])
    a("v", "v", p["Yv"])
    a("v", "phi", g)
    a("v", "b", p["Yb"])
    b("v", "d_ped", p["Yped"])
    a("w", "a", p["Za"])
    a("w", "b", p["Zb"])
    a("w", "w", p["Zw"])
    a("w", "r", p["Zr"])
    b("w", "d_col", p["Zcol"])
    # angular dynamics
    a("p", "u", p["Lu"])
    a("p", "v", p["Lv"])
    a("p", "w", p["Lw"])
    a("p", "b", p["Lb"])
    a("q", "u", p["Mu"])
    a("q", "v", p["Mv"])
    a("q", "w", p["Mw"])
    a("q", "a", p["Ma"])
    b("q", "d_col", p["Mcol"])
    a("r", "v", p["Nv"])
    a("r", "p", p["Np"])
    a("r", "w", p["Nw"])
    a("r", "r", p["Nr"])
    a("r", "r_fb", p["Nrfb"])
    b("r", "d_ped", p["Nped"])
    b("r", "d_col", p["Ncol"])
    # attitude kinematics (hover, small angles)
    a("phi", "p", 1.0)
    a("theta", "q", 1.0)
    # main-rotor flapping: rows divided by tau_f
    tf = p["tau_f"]
    a("a", "q", -1.0)
    a("a", "a", -1.0 / tf)
    a("a", "b", p["Ab"] / tf)
    a("a", "c", p["Ac"] / tf)
    b("a", "d_lat", p["Alat"] / tf)
    b("a", "d_lon", p["Alon"] / tf)
    a("b", "p", -1.0)
    a("b", "b", -1.0 / tf)
    a("b", "a", p["Ba"] / tf)
    a("b", "d", p["Bd"] / tf)
    b("b", "d_lat", p["Blat"] / tf)
    b("b", "d_lon", p["Blon"] / tf)
    # yaw damper (rate gyro feedback)
    a("r_fb", "r", p["Kr"])
    a("r_fb", "r_fb", p["Krfb"])
    # stabiliser bar: rows divided by tau_s
    ts = p["tau_s"]
    a("c", "q", -1.0)
    a("c", "c", -1.0 / ts)
    b("c", "d_lon", p["Clon"] / ts)
    a("d", "p", -1.0)
    a("d", "d", -1.0 / ts)
    b("d", "d_lat", p["Dlat"] / ts)
    return A, B


def _check_params(params: Any, prefix: str = "params") -> dict[str, float]:
    """Validate the parameter table: all 40 keys, finite numbers, time constants > 0."""
    if not isinstance(params, Mapping):
        raise ModelError(f"{prefix}: expected a table of the {len(PARAM_NAMES)} model parameters, got {params!r}")
    unknown = sorted(set(params) - set(PARAM_NAMES))
    if unknown:
        raise ModelError(f"{prefix}.{unknown[0]}: unknown model parameter (known: {', '.join(PARAM_NAMES)})")
    missing = [k for k in PARAM_NAMES if k not in params]
    if missing:
        raise ModelError(f"{prefix}.{missing[0]}: missing (a profile gives all {len(PARAM_NAMES)} parameters)")
    out: dict[str, float] = {}
    for key in PARAM_NAMES:
        value = params[key]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
            raise ModelError(f"{prefix}.{key}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ModelError(f"{prefix}.{key}: expected a finite number, got {value!r}")
        if key in POSITIVE_PARAMS and value <= 0.0:
            raise ModelError(f"{prefix}.{key}: a time constant must be > 0 s, got {value!r}")
        out[key] = value
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class HeliModel:
    """A helicopter hover model: parameters, A and B, and the simulation options of a profile.

    Build it with :meth:`default`, :meth:`from_toml`, :meth:`from_dict` or
    :meth:`from_params`; the constructor is not meant to be called directly. Models compare and
    hash by identity, so discretisations and controller designs can be cached per model.

    Attributes
    ----------
    name : str
        Human-readable profile name.
    params : mapping of str to float
        The 40 derivatives (read-only), keys :data:`PARAM_NAMES`, SI units.
    gravity_m_s2 : float
        Gravitational acceleration.
    servo_tau_s : float
        First-order servo lag time constant, s; 0 = no lag.
    wind : WindSettings
        Default wind of the profile (the CLI may override it).
    source : str
        Where the parameters come from.
    A : ndarray, shape (13, 13)
        Continuous-time state matrix (read-only).
    B : ndarray, shape (13, 4)
        Continuous-time input matrix (read-only).
    """

    name: str
    params: Mapping[str, float]
    gravity_m_s2: float
    servo_tau_s: float
    wind: WindSettings
    source: str
    A: np.ndarray
    B: np.ndarray
    _cache: dict = dataclasses.field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_params(
        cls,
        params: Mapping[str, float],
        *,
        gravity_m_s2: float = 9.81,
        servo_tau_s: float = 0.0,
        wind: WindSettings | None = None,
        name: str = "custom",
        source: str = "",
    ) -> HeliModel:
        """Build a model from the 40 parameters; raises :class:`ModelError` naming a bad key."""
        checked = _check_params(params)
        if not (isinstance(gravity_m_s2, (int, float)) and math.isfinite(gravity_m_s2) and gravity_m_s2 > 0):
            raise ModelError(f"gravity_m_s2: expected a number > 0, got {gravity_m_s2!r}")
        if not (isinstance(servo_tau_s, (int, float)) and math.isfinite(servo_tau_s) and servo_tau_s >= 0):
            raise ModelError(f"servo_tau_s: expected a number >= 0 (0 = no servo lag), got {servo_tau_s!r}")
        A, B = assemble_matrices(checked, float(gravity_m_s2))
        A.setflags(write=False)
        B.setflags(write=False)
        return cls(
            name=name,
            params=types.MappingProxyType(checked),
            gravity_m_s2=float(gravity_m_s2),
            servo_tau_s=float(servo_tau_s),
            wind=wind if wind is not None else WindSettings(),
            source=source,
            A=A,
            B=B,
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "profile") -> HeliModel:
        """Build a model from a parsed profile table (the TOML layout of ``default.toml``)."""
        if not isinstance(data, Mapping):
            raise ModelError(f"{where}: expected a table, got {data!r}")
        try:
            top = from_dict(_ProfileFile, dict(data), error=ModelError)
        except WindError as exc:
            raise ModelError(f"wind.{exc}") from None
        if top.params is None:
            raise ModelError(f"params: missing (the [params] table with the {len(PARAM_NAMES)} model parameters)")
        return cls.from_params(
            top.params,
            gravity_m_s2=top.gravity_m_s2,
            servo_tau_s=top.servo_tau_s,
            wind=top.wind,
            name=top.name,
            source=top.source,
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> HeliModel:
        """Load a profile TOML; every error is a :class:`ModelError` naming the file and key."""
        data = load_toml(path, error=ModelError)
        try:
            return cls.from_dict(data)
        except ModelError as exc:
            raise ModelError(f"{path}: {exc}") from None

    @classmethod
    def default(cls) -> HeliModel:
        """The R-50-class reference hover model shipped as ``profiles/default.toml``."""
        ref = resources.files("heli_model").joinpath("profiles/default.toml")
        with resources.as_file(ref) as path:
            return cls.from_toml(path)

    # ------------------------------------------------------------------ derived
    def replace(self, **changes: Any) -> HeliModel:
        """A new model with some options or parameters changed.

        Keyword arguments named like a parameter (``Xu=...``) change that parameter; the
        others (``gravity_m_s2``, ``servo_tau_s``, ``wind``, ``name``, ``source``) change the
        option. The result has fresh caches.
        """
        params = dict(self.params)
        # the values come from ``changes`` (Any); from_params checks each option
        options: dict[str, Any] = {
            "gravity_m_s2": self.gravity_m_s2,
            "servo_tau_s": self.servo_tau_s,
            "wind": self.wind,
            "name": self.name,
            "source": self.source,
        }
        for key, value in changes.items():
            if key in options:
                options[key] = value
            elif key in params:
                params[key] = value
            else:
                raise ModelError(f"{key}: neither a model parameter nor a profile option")
        return HeliModel.from_params(params, **options)

    def eigenvalues(self) -> np.ndarray:
        """Open-loop eigenvalues of A, (13,) complex, sorted by real part then imaginary part."""
        ev = np.linalg.eigvals(self.A)
        return ev[np.lexsort((ev.imag, ev.real))]

    def cached(self, key: Any, build: Any) -> Any:
        """Per-model memo used by :mod:`dynamics` and :mod:`control` (discretisations, designs)."""
        try:
            return self._cache[key]
        except KeyError:
            value = build()
            self._cache[key] = value
            return value
