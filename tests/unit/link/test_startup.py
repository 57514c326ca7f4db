"""companion.service.startup: the helicopter start-up sequence against a scripted vehicle.

``FakeHeli`` behaves as ArduCopter's helicopter does (see the module under test): arming is
refused with the interlock engaged, the interlock cannot be engaged during the arming delay
(as ``sim-vehicle`` will refuse it), takeoff is refused until the rotor has run up, and its
clock runs 40 times faster than the wall clock so the 2 s + 10 s of a start take a fraction
of a second. The real firmware is in ``tests/integration/test_ardupilot.py``.
"""

from __future__ import annotations

import asyncio
import time
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import ConfigError, VehicleRefused
from companion.service.startup import RotorPlan, StartupSettings, is_airborne, rotor_plan, rpm_settled, start_vehicle

ACCEPTED, FAILED = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_FAILED
TEMPORARILY_REJECTED, UNSUPPORTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED, mavlink.MAV_RESULT_UNSUPPORTED
SCALE = 40.0
HELI_PARAMS = {"H_RSC_MODE": 2.0, "H_RSC_RUNUP_TIME": 10.0}


class FakeHeli:
    """An ArduCopter helicopter as the link sees it (commands, telemetry, vehicle time)."""

    def __init__(
        self,
        params=None,
        *,
        aux_supported=True,
        arm_failures=0,
        prearm_text=None,
        takeoff_refused=False,
        climbs=True,
        pilot_engages_after_s=None,
        interlock_engaged=True,
    ):
        self.params = dict(HELI_PARAMS if params is None else params)
        self.aux_supported = aux_supported
        self.arm_failures = arm_failures
        self.prearm_text = prearm_text
        self.takeoff_refused = takeoff_refused
        self.climbs = climbs
        self.pilot_engages_after_s = pilot_engages_after_s
        self.t0 = time.monotonic()
        self.log: list[tuple[float, str]] = []
        self.armed = False
        self.armed_at = None
        self.interlock = interlock_engaged  # the SITL's RC8 at 1500 counts as engaged
        self.interlock_at = None
        self.mode = 0
        self.height = 0.0
        self.texts: list[str] = []
        self.streams = None
        self.commands = self.waits = self  # the link's parts the start-up uses, in one double

    # vehicle time
    def now_s(self) -> float:
        return (time.monotonic() - self.t0) * SCALE

    def _note(self, what: str) -> None:
        self.log.append((self.now_s(), what))

    @property
    def telemetry(self):
        return SimpleNamespace(
            armed=self.armed,
            in_air=self.height > 0.5,
            height_m=self.height,
            pos_ned_m=[0.0, 0.0, -self.height],
            connected=True,
            prearm_ok=None,
            rotor_rpm=None,
            mode=self.mode,
        )

    # the link's API used by the start-up
    async def read_params(self, names, timeout_s=2.0):
        self._note("params")
        return {n: v for n, v in self.params.items() if n in names}

    async def set_mode(self, mode):
        self._note(f"mode {mode}")
        self.mode = 4 if mode == "GUIDED" else 5

    async def aux_function(self, function, switch, *, timeout_s=3.0):
        self._note(f"aux {function} {switch}")
        if not self.aux_supported:
            return UNSUPPORTED
        if switch == 2:
            if not self.armed or self.now_s() - self.armed_at < 2.0:
                return TEMPORARILY_REJECTED
            self.interlock, self.interlock_at = True, self.now_s()
        else:
            self.interlock = False
        return ACCEPTED

    async def command_result(self, command, params=(), *, what=None, timeout_s=5.0):
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            self._note("arm" if params[0] == 1 else "disarm")
            if params[0] != 1:
                self.armed = False
                return ACCEPTED
            uses_interlock = "H_RSC_MODE" in self.params and self.aux_supported
            if uses_interlock and self.interlock:
                self.texts.append("PreArm: Motor Interlock Enabled")
                return FAILED
            if self.arm_failures > 0:
                self.arm_failures -= 1
                self.texts.append(self.prearm_text or "Arm: Accels inconsistent")
                return FAILED
            self.armed, self.armed_at = True, self.now_s()
            if self.pilot_engages_after_s is not None:
                asyncio.get_running_loop().call_later(self.pilot_engages_after_s / SCALE, self._pilot_engages)
            return ACCEPTED
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            self._note("takeoff")
            needs_rotor = "H_RSC_MODE" in self.params and self.aux_supported
            ready = not needs_rotor or (
                self.interlock and self.interlock_at is not None and self.now_s() - self.interlock_at >= 10.0
            )
            if self.takeoff_refused or not self.armed or not ready:
                return FAILED
            if self.climbs:
                self.height = float(params[6])
            return ACCEPTED
        raise AssertionError(f"unexpected command {command}")

    def _pilot_engages(self):
        self.interlock, self.interlock_at = True, self.now_s()

    async def disarm(self, force=False):
        await self.command_result(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0.0,))

    async def wait_for(self, predicate, timeout_s, what="condition"):
        deadline = time.monotonic() + timeout_s
        while not predicate(self.telemetry):
            if time.monotonic() > deadline:
                from companion.errors import LinkError

                raise LinkError(f"timed out after {timeout_s:g} s waiting for {what}")
            await asyncio.sleep(0.005)
        return self.telemetry

    def refusal_text(self, label, result, since):
        why = f" ({self.texts[-1]})" if self.texts else ""
        return f"{label} refused by the vehicle: {result}{why}"

    def steps(self) -> list[str]:
        return [what for _, what in self.log]

    def time_of(self, what: str) -> float:
        return next(t for t, w in self.log if w == what)


def start(heli, settings=None, alt_m=10.0):
    settings = settings or StartupSettings(retry_interval_s=0.5)
    return asyncio.run(start_vehicle(heli, settings, alt_m, heli.now_s, time_scale=SCALE))


def test_a_helicopter_is_armed_with_the_interlock_low_then_spun_up_and_flown():
    heli = FakeHeli()
    plan = start(heli)
    assert plan.interlock == "command" and plan.runup_time_s == 10.0
    steps = heli.steps()
    assert steps[:4] == ["params", "mode GUIDED", "aux 32 0", "arm"]
    assert "aux 32 2" in steps and steps[-1] == "takeoff" and steps.count("takeoff") == 1
    arm_t = heli.time_of("arm")
    engaged_t = max(t for t, w in heli.log if w == "aux 32 2")
    assert engaged_t - arm_t >= 2.0, "the interlock is engaged only after the arming delay"
    assert heli.time_of("takeoff") - engaged_t >= 10.0 + 1.0, "the takeoff waits for the run-up"
    assert heli.armed and heli.height == 10.0


def test_a_vehicle_without_rotor_parameters_needs_no_interlock():
    heli = FakeHeli(params={})
    plan = start(heli)
    assert plan.interlock == "none"
    assert [s for s in heli.steps() if s.startswith("aux")] == []
    assert heli.steps()[-2:] == ["arm", "takeoff"]


def test_a_vehicle_that_does_not_know_do_aux_function_needs_no_interlock():
    heli = FakeHeli(aux_supported=False)
    plan = start(heli)
    assert plan.interlock == "none" and "UNSUPPORTED" not in plan.reason
    assert heli.steps().count("aux 32 0") == 1 and "aux 32 2" not in heli.steps()
    assert heli.height == 10.0


def test_a_multirotor_profile_skips_the_rotor_entirely():
    heli = FakeHeli(params={})
    start(heli, StartupSettings(vehicle="multirotor", retry_interval_s=0.5))
    assert "params" not in heli.steps()


def test_a_transient_arming_refusal_is_retried():
    heli = FakeHeli(arm_failures=2)
    start(heli)
    assert heli.steps().count("arm") == 3 and heli.height == 10.0


def test_an_arming_refusal_names_the_vehicles_reason_and_leaves_it_disarmed():
    heli = FakeHeli(arm_failures=99, prearm_text="PreArm: Need Position Estimate")
    with pytest.raises(VehicleRefused, match="arm refused by the vehicle: 4 .PreArm: Need Position Estimate"):
        start(heli)
    assert heli.steps().count("arm") == StartupSettings().arm_attempts
    assert not heli.armed and "takeoff" not in heli.steps()


def test_a_refused_takeoff_disarms_the_helicopter_and_puts_the_interlock_low():
    heli = FakeHeli(takeoff_refused=True)
    with pytest.raises(VehicleRefused, match="takeoff to 10 m refused"):
        start(heli)
    assert heli.steps().count("takeoff") == StartupSettings().takeoff_attempts
    steps = heli.steps()
    assert not heli.armed and steps[-2:] == ["disarm", "aux 32 0"]


def test_with_the_pilots_interlock_the_takeoff_waits_for_the_switch():
    heli = FakeHeli(pilot_engages_after_s=4.0, interlock_engaged=False)  # the pilot's switch is low
    plan = start(heli, StartupSettings(interlock="pilot", retry_interval_s=0.5))
    assert plan.interlock == "pilot"
    assert not [s for s in heli.steps() if s.startswith("aux")], "the companion leaves the switch alone"
    assert heli.steps().count("takeoff") > 1 and heli.height == 10.0


def test_with_the_pilots_interlock_left_on_arming_is_refused_with_the_reason():
    heli = FakeHeli()
    with pytest.raises(VehicleRefused, match="Motor Interlock Enabled"):
        start(heli, StartupSettings(interlock="pilot", arm_attempts=1))
    assert not heli.armed


def test_a_helicopter_armed_on_the_ground_is_not_armed_again_nor_its_interlock_dropped():
    heli = FakeHeli()
    heli.armed, heli.armed_at = True, -30.0  # armed long ago, rotor turning
    start(heli)
    steps = heli.steps()
    assert "arm" not in steps and "aux 32 0" not in steps
    assert steps[:3] == ["params", "mode GUIDED", "aux 32 2"] and steps[-1] == "takeoff"


def test_rotor_plan_decisions():
    s = StartupSettings()
    assert rotor_plan(s, {"H_RSC_MODE": 1.0}).interlock == "pilot"  # RC passthrough
    assert rotor_plan(s, {"H_RSC_MODE": 2.0, "ARMING_DELAY_SEC": 3.0}).arming_delay_s == 3.0
    assert rotor_plan(s, {"H_RSC_MODE": 4.0}).runup_time_s == s.runup_time_s
    assert rotor_plan(StartupSettings(vehicle="multirotor"), HELI_PARAMS) == RotorPlan(
        "none", 2.0, 0.0, "vehicle profile multirotor"
    )


def test_airborne_means_armed_and_in_the_air():
    t = SimpleNamespace
    assert is_airborne(t(armed=True, in_air=True, height_m=0.2))
    assert not is_airborne(t(armed=True, in_air=False, height_m=30.0))  # EXTENDED_SYS_STATE rules
    assert is_airborne(t(armed=True, in_air=None, height_m=1.5))  # fallback: height
    assert not is_airborne(t(armed=True, in_air=None, height_m=0.5))
    assert not is_airborne(t(armed=False, in_air=True, height_m=20.0))
    assert not is_airborne(t(armed=True, in_air=None, height_m=None))


def test_rpm_settles_when_it_stops_rising():
    rising = [(0.1 * k, 150.0 * k) for k in range(20)]
    flat = [(2.0 + 0.1 * k, 1500.0 + (k % 2)) for k in range(12)]
    assert not rpm_settled(rising) and rpm_settled(flat) and not rpm_settled(flat[:5])
    assert not rpm_settled([(0.1 * k, 0.0) for k in range(20)])


def test_settings_are_validated():
    with pytest.raises(ConfigError, match="startup.arm_attempts"):
        StartupSettings(arm_attempts=0)
    with pytest.raises(ConfigError, match="startup.retry_interval_s"):
        StartupSettings(retry_interval_s=0.0)
