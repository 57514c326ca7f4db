"""A campaign's spec (``companion campaign run SPEC.toml``): what is flown, how it is judged, when
it stops. One typed tree (``heli_common.typed_config``); a wrong key or value names itself.

Example::

    name = "quick"
    seed = 1
    max_pairs = 2000          # stop here at the latest
    min_pairs = 500           # do not stop before
    tolerance = 0.05          # stop once every ratio is stable within 5 %
    strata = []               # all of them (``companion campaign strata`` lists them)
    settings = ""             # the companion's settings file ("": the defaults)

    [volumes]
    nmac_extra_m = 1.0        # drone scale: NMAC-analogue within radius + 1 m

    [manned]
    hmd_max_m = 1500.0

The spec's hash (``spec_hash``) is stamped on every row: a campaign directory holds one spec.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import typing
from dataclasses import dataclass
from pathlib import Path

from companion.campaign.judge import Volumes
from companion.campaign.strata import STRATA, stratum_names
from companion.config import dict_to_toml
from companion.errors import CompanionError
from companion.flight.fast_time import JobLatency
from heli_common.typed_config import SettingsError, from_dict, load_toml, require_numbers

__all__ = ["CampaignSpec", "MannedSpec", "RobustnessSpec", "SpecError", "load_spec", "spec_hash", "spec_to_toml"]


class SpecError(CompanionError, SettingsError):
    """A campaign spec is wrong; the message names the key."""


@dataclass(frozen=True)
class MannedSpec:
    """Manned traffic's encounter geometry and importance sampling (``[manned]``).

    Nominal: the horizontal miss distance at the closest approach has density proportional to
    itself on ``[0, hmd_max_m]`` (the intruder uniform in area), the vertical one is uniform on
    ``[-vmd_max_m, vmd_max_m]`` (cut at ``min_agl_m``). Proposal: with probability ``near_share``
    uniform on ``[0, hmd_near_m]`` and ``[-vmd_near_m, vmd_near_m]``, else uniform on the whole
    ranges; every encounter's weight is nominal / proposal density.
    """

    hmd_max_m: float = 1500.0
    hmd_near_m: float = 300.0
    vmd_max_m: float = 150.0
    vmd_near_m: float = 40.0
    near_share: float = 0.5
    min_agl_m: float = 15.0
    before_s: float = 50.0
    after_s: float = 20.0

    def __post_init__(self) -> None:
        require_numbers(
            SpecError,
            "manned",
            self,
            positive=("hmd_max_m", "hmd_near_m", "vmd_max_m", "vmd_near_m", "before_s", "after_s"),
            non_negative=("near_share", "min_agl_m"),
        )
        if self.near_share >= 1.0 or self.hmd_near_m > self.hmd_max_m or self.vmd_near_m > self.vmd_max_m:
            raise SpecError("manned: expected near_share < 1, hmd_near_m <= hmd_max_m, vmd_near_m <= vmd_max_m")


@dataclass(frozen=True)
class RobustnessSpec:
    """Ranges of the robustness strata (``[robustness]``), each drawn uniformly per encounter."""

    noise_pos_m: tuple[float, float] = (0.5, 5.0)
    noise_vel_m_s: tuple[float, float] = (0.1, 1.0)
    update_hz: tuple[float, float] = (0.2, 5.0)
    latency_s: tuple[float, float] = (0.0, 0.5)
    dropout: tuple[float, float] = (0.1, 0.6)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            lo, hi = getattr(self, f.name)
            if not 0.0 <= lo <= hi or (f.name == "update_hz" and lo <= 0) or (f.name == "dropout" and hi >= 1):
                raise SpecError(
                    f"robustness.{f.name}: expected 0 <= low <= high (rates > 0, dropout < 1), got [{lo}, {hi}]"
                )


@dataclass(frozen=True)
class CampaignSpec:
    """A campaign (module docstring).

    Parameters
    ----------
    name : str
    seed : int
        Encounter ``i``'s generator is ``numpy.random.default_rng([seed, i])``.
    max_pairs, min_pairs : int
        Encounter pairs flown at most, and at least before stopping on convergence.
    batch_pairs : int
        Encounters per task (a worker's unit; a Dask task costs ~1 ms, a pair ~0.1-1 s).
    tolerance : float
        Relative stability asked of every ratio before stopping.
    check_every : int
        Pairs between convergence checks.
    strata : tuple of str
        The strata flown, in turn (empty: all, ``STRATA``).
    settings : str
        The companion's settings file (relative to the spec's folder), "" for the defaults.
    iterations_per_s : float
        Searches run this many iterations per second of their time budget (reproducible).
    latency : JobLatency
        Modelled job durations on the virtual clock.
    volumes : Volumes
    manned : MannedSpec
    robustness : RobustnessSpec
    """

    name: str = "campaign"
    seed: int = 1
    max_pairs: int = 100_000
    min_pairs: int = 2_000
    batch_pairs: int = 20
    tolerance: float = 0.05
    check_every: int = 1_000
    strata: tuple[str, ...] = ()
    settings: str = ""
    iterations_per_s: float = 3_000.0
    latency: JobLatency = JobLatency()
    volumes: Volumes = Volumes()
    manned: MannedSpec = MannedSpec()
    robustness: RobustnessSpec = RobustnessSpec()

    def __post_init__(self) -> None:
        for name in ("seed", "max_pairs", "min_pairs", "batch_pairs", "check_every"):
            value = getattr(self, name)
            if value < (0 if name == "seed" else 1):
                raise SpecError(f"{name}: must be {'>= 0' if name == 'seed' else '>= 1'}, got {value}")
        if self.min_pairs > self.max_pairs:
            raise SpecError(f"min_pairs: must be <= max_pairs ({self.max_pairs}), got {self.min_pairs}")
        require_numbers(SpecError, "campaign", self, positive=("tolerance", "iterations_per_s"))
        unknown = [s for s in self.strata if s not in STRATA]
        if unknown:
            raise SpecError(f"strata: unknown stratum {unknown[0]!r} (known: {', '.join(stratum_names())})")

    @property
    def stratum_list(self) -> tuple[str, ...]:
        return self.strata or stratum_names()


def load_spec(path: str | Path) -> CampaignSpec:
    """Read a spec file (``SpecError`` naming the file and the key)."""
    try:
        return from_dict(CampaignSpec, load_toml(path, SpecError), "", SpecError)
    except SpecError as exc:
        if str(exc).startswith(str(path)):
            raise
        raise SpecError(f"{path}: {exc}") from None


def _plain(value, kind):
    if dataclasses.is_dataclass(value):
        hints = typing.get_type_hints(type(value))
        return {f.name: _plain(getattr(value, f.name), hints[f.name]) for f in dataclasses.fields(value)}
    if kind is float:
        return float(value)
    if isinstance(value, tuple):
        args = typing.get_args(kind)
        return [_plain(v, args[0] if args else None) for v in value]
    return value


def spec_to_dict(spec: CampaignSpec) -> dict:
    """The spec as plain values, a float field always a float (so that the hash of a spec made
    in code with ``tolerance=1`` is the hash of the same spec read back from its TOML)."""
    return _plain(spec, CampaignSpec)


def spec_hash(spec: CampaignSpec, settings_text: str = "") -> str:
    """SHA-256 (16 hex digits) of the spec and the companion settings file's text."""
    blob = json.dumps({"spec": spec_to_dict(spec), "settings": settings_text}, sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def spec_to_toml(spec: CampaignSpec) -> str:
    """The spec as TOML (what the campaign directory keeps; ``load_spec`` reads it back)."""
    return dict_to_toml(spec_to_dict(spec))
