"""Each encounter flown twice by the fast-time flight executor: the campaign's rows.

``CampaignWorker`` is one worker process's context, built once (the helicopter's LQI designed,
numba compiled, the missions planned) and then asked for rows: ``row(i)`` makes encounter ``i``
from the spec and flies it

- *unmitigated*: the mission flown by ``companion.flight.fast_time.FastTimeFlight`` with no
  threat watched (the same flight for every encounter on a mission, so it is flown once per
  mission and worker);
- *mitigated*: the same executor with the avoidance on, joining the unmitigated flight in the
  air ``JOIN_LEAD_S`` before the first report (its vehicle state then: what comes before cannot
  differ), the intruders' reports delivered as in flight (``companion.campaign.delivery``), jobs taking their modelled durations
  (``JobLatency``) and searches budgeted in iterations, so that the row is the same on any
  machine and with any number of workers.

Both are judged (``companion.campaign.judge``) on the model's own positions against the
intruders' true tracks, on one time grid (a flight that is done holds its last position).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from companion.campaign import judge
from companion.campaign.delivery import DEFAULT_DELIVERY, feed_updates
from companion.campaign.manned import make_manned
from companion.campaign.missions import N_CLUTTERED, Mission, build_mission
from companion.campaign.parametric import OwnFlight, make_parametric
from companion.campaign.spec import CampaignSpec
from companion.campaign.strata import STRATA, Stratum
from companion.campaign.tracks import Encounter
from companion.config import Settings, load_settings
from companion.flight.fast_time import FastTimeFlight, FastTimeResult
from companion.flight.legs import FlightOutcome, LegReplanner
from companion.flight.pipeline import TrajectoryPipeline
from companion.threats.decision.values import DecisionPolicy
from heli_common.frames import LocalFrame
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleUpdate

__all__ = ["CampaignWorker", "HOME", "PairFlight", "MEASURED_COLUMNS", "settings_of"]

log = logging.getLogger(__name__)

#: The local frame's origin: ArduPilot SITL's default home (Canberra).
HOME = LocalFrame(-35.363261, 149.165230, 584.0)
#: Columns measured on this machine (not reproducible; left out when rows are compared).
MEASURED_COLUMNS = ("wall_ms", "cpu_ms", "m_decide_wall_ms")
#: Decision kinds that change the reference because of a threat.
MANOEUVRES = ("evade", "switch", "retime", "hold", "replan")
#: Unmitigated flights fly this long past the mission's nominal duration at most.
SLACK_S = 60.0
#: The mitigated flight joins the unmitigated one this long before the first report (s).
JOIN_LEAD_S = 1.0


@dataclasses.dataclass(frozen=True)
class PairFlight:
    """Both flights of an encounter on one time grid (``report.write_report``'s ``flight_of``).

    Attributes
    ----------
    t_s : ndarray, shape (K,)
    own_u_ned_m, own_m_ned_m : ndarray, shape (K, 3)
        Unmitigated and mitigated positions (the model's).
    threats : list of ndarray, shape (K, 3)
        The intruders' true positions.
    encounter : Encounter
    mitigated : FastTimeResult
    """

    t_s: np.ndarray
    own_u_ned_m: np.ndarray
    own_m_ned_m: np.ndarray
    threats: list
    encounter: Encounter
    mitigated: FastTimeResult


def settings_of(spec: CampaignSpec, spec_dir: Path | None) -> Settings:
    """The companion's settings the campaign flies (``spec.settings``, relative to the spec)."""
    if not spec.settings:
        return Settings()
    path = Path(spec.settings)
    if not path.is_absolute() and spec_dir is not None:
        path = Path(spec_dir) / path
    return load_settings(path)


def _on_grid(t_grid: np.ndarray, t_s: np.ndarray, pos_ned_m: np.ndarray) -> np.ndarray:
    """Positions at ``t_grid``, holding the last one after the flight ended."""
    return np.column_stack([np.interp(t_grid, t_s, pos_ned_m[:, a]) for a in range(3)])


class CampaignWorker:
    """One worker's context (module docstring).

    Parameters
    ----------
    spec : CampaignSpec
    settings : Settings
        The companion's settings.
    spec_hash : str
    """

    def __init__(self, spec: CampaignSpec, settings: Settings, spec_hash: str) -> None:
        self.spec = spec
        self.settings = settings
        self.spec_hash = spec_hash
        self.update = VehicleUpdate.build(HeliModel.default())
        self.pipeline = TrajectoryPipeline.from_settings(
            settings.smoothing, settings.planning, iterations_per_s=spec.iterations_per_s
        )
        self.policy = dataclasses.replace(
            DecisionPolicy.from_settings(settings),
            pipeline=self.pipeline,
            modelled_lead_s=(spec.latency.decision_s, spec.latency.replan_s),
        )
        self._missions: dict[str, Mission] = {}
        self._unmitigated: dict[str, FastTimeResult] = {}
        self._models: dict[str, object] = {}

    # ------------------------------------------------------------------ cached parts
    def mission(self, name: str) -> Mission:
        if name not in self._missions:
            self._missions[name] = build_mission(name, self.settings, iterations_per_s=self.spec.iterations_per_s)
        return self._missions[name]

    def unmitigated(self, name: str) -> FastTimeResult:
        """The mission flown ignoring threats (once per mission)."""
        if name not in self._unmitigated:
            m = self.mission(name)
            self._unmitigated[name] = FastTimeFlight(
                m.legs,
                self.settings,
                start_yaw_rad=m.start_yaw_rad,
                update=self.update,
                world=m.world,
                replanner=LegReplanner.in_world(m.world, self.pipeline, self.settings.flight),
                job_latency=self.spec.latency,
            ).run(max_s=m.duration_s + SLACK_S)
        return self._unmitigated[name]

    def traffic_model(self, kind: str):
        from companion.campaign.traffic_model import load_model

        if kind not in self._models:
            self._models[kind] = load_model(kind)
        return self._models[kind]

    def warm(self) -> None:
        """Plan and fly every mission once (numba compiles, the worlds are built)."""
        for name in {self.mission_of(i, STRATA[s]) for i, s in enumerate(self.spec.stratum_list)}:
            self.unmitigated(name)

    # ------------------------------------------------------------------ one encounter
    def stratum_of(self, index: int) -> Stratum:
        names = self.spec.stratum_list
        return STRATA[names[index % len(names)]]

    def mission_of(self, index: int, stratum: Stratum) -> str:
        if stratum.mission != "cluttered":
            return stratum.mission
        return f"cluttered-{(index // len(self.spec.stratum_list)) % N_CLUTTERED}"

    def _delivery(self, stratum: Stratum, rng: np.random.Generator) -> dict:
        delivery = dict(DEFAULT_DELIVERY)
        r = self.spec.robustness
        if stratum.robustness == "noise":
            delivery["noise_pos_m"] = float(rng.uniform(*r.noise_pos_m))
            delivery["noise_vel_m_s"] = float(rng.uniform(*r.noise_vel_m_s))
        elif stratum.robustness == "rate":
            delivery["update_hz"] = float(rng.uniform(*r.update_hz))
        elif stratum.robustness == "latency":
            delivery["latency_s"] = float(rng.uniform(*r.latency_s))
        elif stratum.robustness == "dropout":
            delivery["dropout"] = float(rng.uniform(*r.dropout))
        return delivery

    def encounter(self, index: int) -> Encounter:
        """Encounter ``index`` of the spec (pure: the same spec and index, the same encounter)."""
        stratum = self.stratum_of(index)
        name = self.mission_of(index, stratum)
        mission = self.mission(name)
        base = self.unmitigated(name)
        own = OwnFlight(base.t_s, base.pos_ned_m)
        rng = np.random.default_rng([self.spec.seed, index])
        if stratum.source == "manned":
            enc = make_manned(
                index,
                stratum.name,
                stratum.geometry,
                self.traffic_model(stratum.geometry),
                own,
                self.spec.manned,
                self.settings.adsb,
                rng,
            )
        else:
            enc = make_parametric(
                index,
                stratum.name,
                stratum.geometry,
                stratum.mission,
                own,
                mission.goal_ned_m,
                self._delivery(stratum, rng),
                rng,
            )
        return dataclasses.replace(enc, mission=name)

    def fly(self, index: int) -> PairFlight:
        """Encounter ``index`` flown twice, on one grid."""
        enc = self.encounter(index)
        m = self.mission(enc.mission)
        rng = np.random.default_rng([self.spec.seed, index, 1])
        updates = feed_updates(
            enc.intruders, enc.traffic, enc.delivery, rng, home=HOME, adsb_settings=self.settings.adsb
        )
        flight = FastTimeFlight(
            m.legs,
            self.settings,
            threats=updates,
            policy=self.policy,
            seed=int(rng.integers(2**31)),
            start_yaw_rad=m.start_yaw_rad,
            update=self.update,
            world=m.world,
            job_latency=self.spec.latency,
            home=HOME,
            replanner=LegReplanner.in_world(m.world, self.pipeline, self.settings.flight),
        )
        base = self.unmitigated(enc.mission)
        k = min(int(np.searchsorted(base.t_s, enc.first_report_t_s - JOIN_LEAD_S)), len(base.states) - 1)
        mitigated = flight.run(max_s=enc.end_t_s, from_s=float(base.t_s[k]), from_state=base.states[k])
        dt = 1.0 / self.settings.link.setpoint_rate_hz
        grid = np.arange(enc.first_report_t_s, enc.end_t_s + 0.5 * dt, dt)
        threats = [tr.position_at(grid) for tr in enc.intruders]
        return PairFlight(
            grid,
            _on_grid(grid, base.t_s, base.pos_ned_m),
            _on_grid(grid, mitigated.t_s, mitigated.pos_ned_m),
            threats,
            enc,
            mitigated,
        )

    def row(self, index: int) -> dict:
        """Encounter ``index``'s row (``companion.campaign.store.SCHEMA``)."""
        wall0, cpu0 = time.perf_counter(), time.process_time()
        pair = self.fly(index)
        enc, m = pair.encounter, self.mission(pair.encounter.mission)
        manned = enc.traffic != "drone"
        row = {
            "id": int(index),
            "stratum": enc.stratum,
            "source": "manned" if manned else "parametric",
            "traffic": enc.traffic,
            "world": STRATA[enc.stratum].world,
            "mission": enc.mission,
            "seed": int(self.spec.seed),
            "spec_hash": self.spec_hash,
            "weight": float(enc.weight),
            "n_threats": len(enc.intruders),
        }
        base = self.unmitigated(enc.mission)
        for prefix, track, outcome in (
            ("u_", pair.own_u_ned_m, base.outcome),
            ("m_", pair.own_m_ned_m, pair.mitigated.outcome),
        ):
            sep = judge.separation(pair.t_s, track, enc.intruders, manned, self.spec.volumes)
            row.update(
                {
                    f"{prefix}collision": sep.collision,
                    f"{prefix}nmac": sep.nmac,
                    f"{prefix}lowc": sep.lowc,
                    f"{prefix}min_sep_m": sep.min_sep_m,
                    f"{prefix}hmd_m": list(sep.hmd_m),
                    f"{prefix}vmd_m": list(sep.vmd_m),
                    f"{prefix}obstacle_entries": judge.entries(
                        track, m.obstacles, m.bounds_min_ned_m, m.bounds_max_ned_m
                    ),
                    f"{prefix}fence_entries": judge.entries(track, m.fences, m.bounds_min_ned_m, m.bounds_max_ned_m),
                    f"{prefix}completed": outcome == FlightOutcome.COMPLETED,
                    f"{prefix}path_m": judge.path_length_m(track),
                }
            )
        row.update(self._decision_columns(pair.mitigated.decisions, enc.first_report_t_s))
        row["m_extra_path_m"] = row["m_path_m"] - row["u_path_m"]
        row.update({key: float(enc.delivery[key]) for key in DEFAULT_DELIVERY})
        row["wall_ms"] = (time.perf_counter() - wall0) * 1e3
        row["cpu_ms"] = (time.process_time() - cpu0) * 1e3
        return row

    @staticmethod
    def _decision_columns(decisions: list, first_report_t_s: float) -> dict:
        kinds = ["resume" if d.get("trigger") == "resume" else str(d["event"]) for d in decisions]
        manoeuvres = [k for k in kinds if k in MANOEUVRES]
        first = next((d["t_s"] for d, k in zip(decisions, kinds) if k in MANOEUVRES), None)
        return {
            "m_alerted": bool(manoeuvres),
            "m_manoeuvred": bool(manoeuvres),
            "m_alert_t_s": float("nan") if first is None else float(first - first_report_t_s),
            "m_decisions": kinds,
            "m_latency_ms": [
                float(d["latency_ms"]) if d.get("latency_ms") is not None else float("nan") for d in decisions
            ],
            "m_decide_wall_ms": [float(d.get("decide_ms") or 0.0) for d in decisions],
        }
