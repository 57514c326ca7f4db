"""The campaign's strata: every kind of encounter, where it is flown and how it is heard.

A stratum is a value: a source (``parametric`` geometry or ``manned`` traffic from MIT LL's
encounter models), the mission it meets the helicopter on, and, for the robustness strata, which
of the reports' qualities is degraded. Encounter ``i`` of a campaign belongs to stratum
``strata[i % len(strata)]``: every stratum gets its share, whatever the number of workers.

- ``<geometry>/<world>``: the parametric geometries (``companion.campaign.parametric``) head-on,
  crossing, overtaking, pop-ups near and far, pop-up movers, two or three at once, intruders that
  turn or climb, each in open air, among obstacles (``cluttered``) and beside fences;
- ``above/climb``, ``above/descend``, ``below/climb``, ``below/descend``: from above and below on
  climbing and descending legs;
- ``robust/<quality>``: crossing intruders in open air heard with position and
  velocity noise (``noise``), a slow or fast update rate (``rate``), late (``latency``) or with
  lost reports (``dropout``), drawn from ``[robustness]``;
- ``manned/rotorcraft``, ``manned/fixedwing``: tracks sampled from the models, heard as
  ADSB_VEHICLE at 1 Hz, on the ``long`` mission.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Stratum", "STRATA", "stratum_names", "ROBUSTNESS_QUALITIES"]

WORLDS = ("open", "cluttered", "fenced")
LEVEL_GEOMETRIES = (
    "head_on",
    "crossing",
    "overtaking",
    "popup_near",
    "popup_far",
    "popup_mover",
    "multi",
    "turning",
    "climbing",
)
ROBUSTNESS_QUALITIES = ("noise", "rate", "latency", "dropout")


@dataclass(frozen=True)
class Stratum:
    """One stratum.

    Attributes
    ----------
    name : str
    source : str
        ``parametric`` or ``manned``.
    geometry : str
        The parametric geometry, or the manned model (``rotorcraft``, ``fixedwing``).
    mission : str
        The mission kind (``companion.campaign.missions``).
    robustness : str or None
        The degraded quality (``ROBUSTNESS_QUALITIES``).
    """

    name: str
    source: str
    geometry: str
    mission: str
    robustness: str | None = None

    @property
    def traffic(self) -> str:
        return self.geometry if self.source == "manned" else "drone"

    @property
    def world(self) -> str:
        return {"cluttered": "cluttered", "fenced": "fenced"}.get(self.mission, "open")


def _catalogue() -> dict[str, Stratum]:
    out: list[Stratum] = []
    for geometry in LEVEL_GEOMETRIES:
        out += [Stratum(f"{geometry}/{world}", "parametric", geometry, world) for world in WORLDS]
    out += [Stratum(f"{g}/{m}", "parametric", g, m) for g in ("above", "below") for m in ("climb", "descend")]
    out += [Stratum(f"robust/{q}", "parametric", "crossing", "open", q) for q in ROBUSTNESS_QUALITIES]
    out += [Stratum(f"manned/{m}", "manned", m, "long") for m in ("rotorcraft", "fixedwing")]
    return {s.name: s for s in out}


#: Every stratum, by name.
STRATA: dict[str, Stratum] = _catalogue()


def stratum_names() -> tuple[str, ...]:
    """Every stratum's name, in the catalogue's order."""
    return tuple(STRATA)
