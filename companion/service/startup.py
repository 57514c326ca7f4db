"""Helicopter start-up and joining: arm, motor interlock, rotor run-up, takeoff (ArduCopter heli).

An ArduPilot helicopter has a rotor speed controller (RSC) behind a *motor interlock*: the rotor
turns only with the interlock engaged (RC8 high, or MAV_CMD_DO_AUX_FUNCTION function 32
MOTOR_INTERLOCK at switch position 2), and then needs ``H_RSC_RUNUP_TIME`` to reach flight speed.
ArduCopter refuses to arm with the interlock engaged ("PreArm: Motor Interlock Enabled"; the
SITL's RC8 at 1500 counts as engaged), keeps the interlock off for ``ARMING_DELAY_SEC`` (2 s,
a compile-time constant in ArduCopter) after arming, refuses NAV_TAKEOFF until the interlock
is on, and refuses to switch an armed helicopter into GUIDED before the run-up is complete.
With the interlock off it disarms after DISARM_DELAY (10 s).

:func:`start_vehicle` is the whole start, one function per step, times in *vehicle* seconds
(``now_s``: the vehicle clock of ``time_boot_ms``, so a sped-up SITL waits its own seconds):

1. :func:`read_rotor_parameters` (PARAM_REQUEST_READ of ``H_RSC_MODE``, ``H_RSC_RUNUP_TIME``,
   ``ARMING_DELAY_SEC``) and :func:`rotor_plan`: how the interlock is handled. A vehicle
   without ``H_RSC_MODE``, a ``multirotor`` profile, or one that answers DO_AUX_FUNCTION with
   UNSUPPORTED needs no interlock (logged);
2. GUIDED while disarmed;
3. :func:`interlock_low` (DO_AUX_FUNCTION 32, switch 0), so that arming is allowed, then
   :func:`wait_prearm`: ArduCopter runs its other pre-arm checks only once the interlock is
   low, and its IMUs must then agree for 10 s ("Accels inconsistent"); the vehicle's SYS_STATUS
   says when they pass (a vehicle that does not report them is not waited for);
4. :func:`arm`, with bounded retries and the vehicle's own reason (its STATUSTEXT) on refusal;
5. :func:`wait_arming_delay`, then :func:`engage_interlock` (switch 2), or, with
   ``interlock = "pilot"`` (or ``H_RSC_MODE`` 1, passthrough), the pilot's switch;
6. :func:`wait_runup`: ``H_RSC_RUNUP_TIME`` plus a margin after the interlock, and, when the
   vehicle sends RPM, until the rotor speed has settled;
7. :func:`take_off` with bounded retries, then the climb.

A start that fails is undone by :func:`abandon_start`: a vehicle on the ground is disarmed
(interlock low again), one that left the ground holds where it is (LOITER), unless a pilot or
the autopilot took it out of GUIDED (:func:`left_guided`, also watched during the climb): then
nothing more is commanded. A refusal raises
``VehicleRefused`` (``companion run`` exits 3), a start that ends in the air ``FlightAborted``
(exit 4).

:func:`is_airborne` decides whether the companion *joins* a flying vehicle instead (no arming,
no takeoff): EXTENDED_SYS_STATE in the air, or, without it, armed and above 1 m.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import ConfigError, FlightAborted, LinkError, VehicleRefused
from heli_common.ardupilot_ids import AUX_FUNCTION_MOTOR_INTERLOCK as AUX_MOTOR_INTERLOCK
from heli_common.ardupilot_ids import SWITCH_HIGH, SWITCH_LOW
from heli_common.mavlink_ids import COPTER_MODES
from heli_common.typed_config import require_int, require_numbers

__all__ = [
    "StartupSettings",
    "RotorPlan",
    "rotor_plan",
    "is_airborne",
    "start_vehicle",
    "read_rotor_parameters",
    "interlock_low",
    "wait_prearm",
    "arm",
    "wait_arming_delay",
    "engage_interlock",
    "wait_runup",
    "take_off",
    "abandon_start",
    "rpm_settled",
    "AUX_MOTOR_INTERLOCK",
    "RSC_PARAMETERS",
]

log = logging.getLogger(__name__)

#: H_RSC_MODE 1: the rotor follows the RC8 input directly (DO_AUX_FUNCTION does not drive it).
RSC_MODE_PASSTHROUGH = 1
RSC_PARAMETERS = ("H_RSC_MODE", "H_RSC_RUNUP_TIME", "ARMING_DELAY_SEC")

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED


@dataclass(frozen=True)
class StartupSettings:
    """How the companion starts (or joins) the vehicle (``[startup]``).

    Parameters
    ----------
    vehicle : str
        ``helicopter`` (default: motor interlock and rotor run-up when the vehicle has an RSC)
        or ``multirotor`` (arm and take off, no interlock).
    interlock : str
        ``command``: the companion engages the interlock (DO_AUX_FUNCTION 32) after the
        arming delay; ``pilot``: the safety pilot engages it with the RC switch, the companion
        waits (and retries the takeoff) for up to ``pilot_timeout_s``.
    arming_delay_s : float
        Used when the vehicle has no ``ARMING_DELAY_SEC`` parameter (ArduCopter: a constant
        of 2 s).
    runup_time_s : float
        Used when the vehicle has no ``H_RSC_RUNUP_TIME`` (ArduPilot's default 10 s).
    runup_margin_s : float
        Added to the run-up time before the takeoff.
    pilot_timeout_s : float
        How long to wait for the pilot's interlock (vehicle seconds). ArduCopter disarms an
        armed helicopter whose interlock stays off for DISARM_DELAY (10 s).
    prearm_timeout_s : float
        How long to wait for the vehicle's pre-arm checks to pass before arming anyway (the
        refusal then names the failing check; vehicle seconds).
    arm_attempts, takeoff_attempts : int
        Bounded retries of a refused arm or takeoff.
    retry_interval_s : float
        Between two attempts (vehicle seconds).
    param_timeout_s : float
        How long to wait for the RSC parameters (wall clock).
    join_min_height_m : float
        Without EXTENDED_SYS_STATE, an armed vehicle higher than this above home is flying.
    """

    vehicle: Literal["helicopter", "multirotor"] = "helicopter"
    interlock: Literal["command", "pilot"] = "command"
    arming_delay_s: float = 2.0
    runup_time_s: float = 10.0
    runup_margin_s: float = 1.0
    pilot_timeout_s: float = 60.0
    prearm_timeout_s: float = 30.0
    arm_attempts: int = 4
    takeoff_attempts: int = 5
    retry_interval_s: float = 2.0
    param_timeout_s: float = 2.0
    join_min_height_m: float = 1.0

    def __post_init__(self) -> None:
        require_numbers(
            ConfigError,
            "startup",
            self,
            positive=("pilot_timeout_s", "prearm_timeout_s", "retry_interval_s", "param_timeout_s"),
            non_negative=("arming_delay_s", "runup_time_s", "runup_margin_s", "join_min_height_m"),
        )
        require_int(ConfigError, "startup", "arm_attempts", self.arm_attempts, 1, 20)
        require_int(ConfigError, "startup", "takeoff_attempts", self.takeoff_attempts, 1, 50)


@dataclass(frozen=True)
class RotorPlan:
    """How this vehicle is started: ``interlock`` is ``command``, ``pilot`` or ``none``."""

    interlock: str
    arming_delay_s: float
    runup_time_s: float
    reason: str


def rotor_plan(settings: StartupSettings, params: dict) -> RotorPlan:
    """Decide the interlock handling from the settings and the parameters the vehicle has.

    Parameters
    ----------
    settings : StartupSettings
    params : dict
        Name -> value of the ``RSC_PARAMETERS`` the vehicle answered (absent: not on it).

    Examples
    --------
    >>> rotor_plan(StartupSettings(), {"H_RSC_MODE": 2.0, "H_RSC_RUNUP_TIME": 10.0}).interlock
    'command'
    >>> rotor_plan(StartupSettings(), {}).interlock
    'none'
    """
    delay = float(params.get("ARMING_DELAY_SEC", settings.arming_delay_s))
    runup = float(params.get("H_RSC_RUNUP_TIME", settings.runup_time_s))
    if settings.vehicle == "multirotor":
        return RotorPlan("none", delay, 0.0, "vehicle profile multirotor")
    if "H_RSC_MODE" not in params:
        return RotorPlan("none", delay, 0.0, "no H_RSC_MODE parameter: no rotor speed controller")
    mode = int(params["H_RSC_MODE"])
    if mode == RSC_MODE_PASSTHROUGH and settings.interlock == "command":
        return RotorPlan(
            "pilot",
            delay,
            runup,
            "H_RSC_MODE 1 (RC passthrough): the rotor follows the pilot's RC8, DO_AUX_FUNCTION cannot engage it",
        )
    return RotorPlan(settings.interlock, delay, runup, f"H_RSC_MODE {mode}")


def left_guided(tele) -> bool:
    """Has the vehicle left GUIDED (a pilot's or the autopilot's mode change: the companion's
    commands stop at once)? False while the mode is not known yet."""
    mode = getattr(tele, "mode", None)
    return mode is not None and mode != COPTER_MODES["GUIDED"]


def is_airborne(tele, min_height_m: float = 1.0) -> bool:
    """True for an armed vehicle that flies: EXTENDED_SYS_STATE in the air (or taking off or
    landing); without it, higher than ``min_height_m`` above home."""
    if not tele.armed:
        return False
    if tele.in_air is not None:
        return bool(tele.in_air)
    height = tele.height_m
    return height is not None and height > min_height_m


def rpm_settled(samples, window_s: float = 1.0, tolerance: float = 0.02) -> bool:
    """True when the rotor speed has settled: over the last ``window_s`` of ``samples``
    ((vehicle_s, rpm) pairs, oldest first) it is above zero and varies by less than
    ``tolerance`` of its value."""
    if not samples:
        return False
    t_end = samples[-1][0]
    if t_end - samples[0][0] < window_s:
        return False
    recent = [rpm for t, rpm in samples if t >= t_end - window_s]
    top = max(recent)
    return top > 0.0 and (top - min(recent)) <= tolerance * top


async def wait_vehicle_s(now_s: Callable[[], float], duration_s: float, poll_s: float = 0.02) -> None:
    """Sleep ``duration_s`` of vehicle time."""
    end = now_s() + duration_s
    while now_s() < end:
        await asyncio.sleep(poll_s)


# ---------------------------------------------------------------------------- the steps
async def read_rotor_parameters(link, settings: StartupSettings) -> dict:
    """The RSC parameters the vehicle has (PARAM_REQUEST_READ); {} for a multirotor profile."""
    if settings.vehicle == "multirotor":
        return {}
    return await link.commands.read_params(RSC_PARAMETERS, timeout_s=settings.param_timeout_s)


async def interlock_low(link) -> bool:
    """Put the motor interlock low (DO_AUX_FUNCTION 32, switch 0) so that arming is allowed.

    Returns False when the vehicle does not know the command (it needs no interlock).

    Raises
    ------
    VehicleRefused
        Any other refusal, or no answer.
    """
    sent = time.monotonic()
    result = await link.commands.aux_function(AUX_MOTOR_INTERLOCK, SWITCH_LOW)
    if result == UNSUPPORTED:
        return False
    if result != ACCEPTED:
        raise VehicleRefused(
            link.commands.refusal_text("motor interlock low (DO_AUX_FUNCTION 32)", result, sent), result
        )
    return True


async def wait_prearm(link, settings: StartupSettings, now_s) -> bool:
    """Wait (up to ``prearm_timeout_s`` of vehicle time) until the vehicle reports its pre-arm
    checks passing (SYS_STATUS); returns whether they did. A vehicle that does not report them
    (``prearm_ok`` None once SYS_STATUS has arrived, or after two seconds) is not waited for."""
    start = now_s()
    await asyncio.sleep(0.1)
    streams = getattr(link, "streams", None)
    while True:
        ok = link.telemetry.prearm_ok
        elapsed = now_s() - start
        if ok:
            return True
        if ok is None and (elapsed > 2.0 or (streams is not None and streams.seen("SYS_STATUS"))):
            return False
        if elapsed > settings.prearm_timeout_s:
            log.warning(
                "the vehicle's pre-arm checks still fail after %.0f s: arming anyway", settings.prearm_timeout_s
            )
            return False
        await asyncio.sleep(0.05)


async def arm(link, settings: StartupSettings, now_s) -> float:
    """Arm, retrying a refusal ``arm_attempts`` times; returns the vehicle time of arming.

    Raises
    ------
    VehicleRefused
        Every attempt refused (the message carries the vehicle's reason, e.g.
        ``PreArm: Motor Interlock Enabled``), or the vehicle never reported itself armed.
    """
    message, result = "arm: no attempt", None
    for attempt in range(1, settings.arm_attempts + 1):
        sent = time.monotonic()
        result = await link.commands.command_result(
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), what="arm", timeout_s=5.0
        )
        if result == ACCEPTED:
            armed_at = now_s()
            await link.waits.wait_for(lambda t: bool(t.armed), 5.0, "the armed state")
            return armed_at
        await asyncio.sleep(0.3)  # the vehicle's reason (STATUSTEXT) may follow the ack
        message = link.commands.refusal_text("arm", result, sent)
        log.warning("%s (attempt %d of %d)", message, attempt, settings.arm_attempts)
        if attempt < settings.arm_attempts:
            await wait_vehicle_s(now_s, settings.retry_interval_s)
    raise VehicleRefused(message, result)


async def wait_arming_delay(link, plan: RotorPlan, armed_at_s: float, now_s) -> None:
    """Wait until ``plan.arming_delay_s`` (vehicle time) has passed since arming."""
    remaining = armed_at_s + plan.arming_delay_s + 0.1 - now_s()
    if remaining > 0:
        await wait_vehicle_s(now_s, remaining)
    if not link.telemetry.armed:
        raise VehicleRefused("the vehicle disarmed during the arming delay")


async def engage_interlock(link, plan: RotorPlan, settings: StartupSettings, now_s) -> bool:
    """Engage the motor interlock (DO_AUX_FUNCTION 32, switch 2), retrying a refusal for a few
    arming delays; returns False when the vehicle does not know the command.

    Raises
    ------
    VehicleRefused
        Still refused after ``max(3 s, 3 x arming delay)`` of vehicle time.
    """
    deadline = now_s() + max(3.0, 3.0 * plan.arming_delay_s)
    while True:
        sent = time.monotonic()
        result = await link.commands.aux_function(AUX_MOTOR_INTERLOCK, SWITCH_HIGH)
        if result == ACCEPTED:
            return True
        if result == UNSUPPORTED:
            return False
        if now_s() > deadline or not link.telemetry.armed:
            raise VehicleRefused(
                link.commands.refusal_text("motor interlock (DO_AUX_FUNCTION 32 high)", result, sent), result
            )
        await wait_vehicle_s(now_s, min(0.5, settings.retry_interval_s))


async def wait_runup(link, plan: RotorPlan, settings: StartupSettings, now_s) -> float:
    """Wait for the rotor run-up: ``runup_time_s + runup_margin_s`` of vehicle time, then, when
    the vehicle reports RPM, until the rotor speed has settled (at most one more run-up time).
    Returns the last rotor RPM (nan without RPM).

    Raises
    ------
    VehicleRefused
        The vehicle disarmed meanwhile.
    """
    start = now_s()
    ready_at = start + plan.runup_time_s + settings.runup_margin_s
    give_up = ready_at + plan.runup_time_s
    samples: list[tuple[float, float]] = []
    while True:
        tele = link.telemetry
        if not tele.armed:
            raise VehicleRefused("the vehicle disarmed during the rotor run-up")
        t = now_s()
        if tele.rotor_rpm is not None:
            samples.append((t, float(tele.rotor_rpm)))
            samples = [s for s in samples if s[0] >= t - 2.0]
        if t >= ready_at and (tele.rotor_rpm is None or rpm_settled(samples) or t >= give_up):
            rpm = math.nan if tele.rotor_rpm is None else float(tele.rotor_rpm)
            log.info(
                "rotor run-up done after %.1f s (vehicle time)%s",
                t - start,
                "" if math.isnan(rpm) else f", rotor at {rpm:.0f} rpm",
            )
            return rpm
        await asyncio.sleep(0.05)


async def take_off(link, alt_m: float, attempts: int, retry_s: float, now_s, deadline_s: float | None = None) -> int:
    """NAV_TAKEOFF to ``alt_m`` above home, retried until accepted; returns the attempts used.

    ``deadline_s`` (vehicle time) replaces the attempt count when given (waiting for the
    pilot's interlock: the takeoff is refused until it is engaged).

    Raises
    ------
    VehicleRefused
        Still refused (with the vehicle's reason).
    """
    attempt = 0
    while True:
        attempt += 1
        sent = time.monotonic()
        result = await link.commands.command_result(
            mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, float(alt_m)), what=f"takeoff to {alt_m:g} m", timeout_s=5.0
        )
        if result == ACCEPTED:
            return attempt
        out_of_time = now_s() >= deadline_s if deadline_s is not None else attempt >= attempts
        if out_of_time or not link.telemetry.armed:
            await asyncio.sleep(0.3)
            raise VehicleRefused(link.commands.refusal_text(f"takeoff to {alt_m:g} m", result, sent), result)
        log.info("takeoff refused (%s), attempt %d; retrying", result, attempt)
        await wait_vehicle_s(now_s, retry_s)


async def abandon_start(link, interlock_commanded: bool, reason: str, min_height_m: float = 1.0) -> str:
    """Undo a start that failed: disarm a vehicle on the ground (interlock low again), hold one
    that left the ground (LOITER). Returns what was done; never raises."""
    try:
        tele = link.telemetry
        if not tele.connected or not tele.armed:
            outcome = "left disarmed on the ground"
        elif is_airborne(tele, min_height_m) and left_guided(tele):
            outcome = f"left in {tele.mode_name}: a pilot's or the autopilot's mode, not commanded further"
        elif is_airborne(tele, min_height_m):
            await link.commands.set_mode("LOITER")
            outcome = "holding in the air (LOITER)"
        else:
            try:
                await link.commands.disarm()
            except LinkError:
                await link.commands.disarm(force=True)
            await link.waits.wait_for(lambda t: t.armed is False, 5.0, "the disarm")
            outcome = "disarmed on the ground"
        if interlock_commanded and not link.telemetry.armed:
            await link.commands.aux_function(AUX_MOTOR_INTERLOCK, SWITCH_LOW)
    except Exception as exc:  # noqa: BLE001 - the original error is what the user must see
        outcome = f"could not be made safe ({exc})"
    log.error("start-up failed (%s): vehicle %s", reason, outcome)
    return outcome


# ---------------------------------------------------------------------------- the whole start
async def start_vehicle(
    link,
    settings: StartupSettings,
    alt_m: float,
    now_s: Callable[[], float],
    *,
    time_scale: float = 1.0,
    climb_speed_m_s: float = 1.0,
    event=None,
) -> RotorPlan:
    """GUIDED, interlock low, arm, interlock, run-up, takeoff to ``alt_m``, climb (module docstring).

    Parameters
    ----------
    link : companion.link.VehicleLink
    settings : StartupSettings
    alt_m : float
        Takeoff altitude above home (m), > 0.
    now_s : callable () -> float
        Vehicle time (s).
    time_scale : float
        Vehicle seconds per wall-clock second (for the wall-clock timeouts).
    climb_speed_m_s : float
        Expected climb speed, for the climb's timeout.
    event : callable (name, **fields), optional
        Told about each step (the daemon's event log).

    Raises
    ------
    VehicleRefused
        A refusal before the vehicle left the ground; it is disarmed again.
    FlightAborted
        The takeoff was accepted but the climb did not complete; the vehicle holds or is
        disarmed on the ground.
    """
    tell = event or (lambda name, **fields: None)
    params = await read_rotor_parameters(link, settings)
    plan = rotor_plan(settings, params)
    log.info(
        "start-up: interlock %s (%s); arming delay %.1f s, run-up %.1f s",
        plan.interlock,
        plan.reason,
        plan.arming_delay_s,
        plan.runup_time_s,
    )
    await link.commands.set_mode("GUIDED")
    commanded = False
    already_armed = bool(link.telemetry.armed)  # e.g. on the ground with the rotor running
    if plan.interlock == "command" and not already_armed:
        commanded = await interlock_low(link)
        if not commanded:
            plan = RotorPlan(
                "none", plan.arming_delay_s, 0.0, "DO_AUX_FUNCTION unsupported by the vehicle: no interlock"
            )
            log.info("start-up: %s", plan.reason)
    try:
        if already_armed:
            log.info("start-up: the vehicle is already armed on the ground")
            armed_at = now_s() - plan.arming_delay_s
        else:
            if await wait_prearm(link, settings, now_s):
                log.info("start-up: the vehicle's pre-arm checks pass")
            armed_at = await arm(link, settings, now_s)
            tell("armed", interlock=plan.interlock)
        deadline = None
        if plan.interlock == "command":
            await wait_arming_delay(link, plan, armed_at, now_s)
            if await engage_interlock(link, plan, settings, now_s):
                commanded = True
                tell("interlock", switch="high")
                rpm = await wait_runup(link, plan, settings, now_s)
                tell("rotor_runup", seconds=plan.runup_time_s, rpm=None if math.isnan(rpm) else round(rpm))
            else:
                log.info("start-up: DO_AUX_FUNCTION unsupported after arming: no interlock")
        elif plan.interlock == "pilot":
            log.warning(
                "waiting up to %.0f s for the pilot to engage the motor interlock (the "
                "vehicle disarms itself after DISARM_DELAY with the interlock off)",
                settings.pilot_timeout_s,
            )
            deadline = now_s() + settings.pilot_timeout_s
        attempts = await take_off(link, alt_m, settings.takeoff_attempts, settings.retry_interval_s, now_s, deadline)
        tell("takeoff", alt_m=alt_m, attempts=attempts)
    except (VehicleRefused, LinkError, asyncio.CancelledError) as exc:
        await asyncio.shield(abandon_start(link, commanded, str(exc) or type(exc).__name__, settings.join_min_height_m))
        raise
    wait_vehicle = 30.0 + 3.0 * alt_m / max(climb_speed_m_s, 0.1)
    if plan.interlock == "pilot":
        wait_vehicle += plan.runup_time_s + settings.runup_margin_s
    try:
        await link.waits.wait_for(
            lambda t: (
                left_guided(t)
                or (t.height_m is not None and t.pos_ned_m is not None and -t.pos_ned_m[2] >= alt_m - 0.5)
            ),
            10.0 + wait_vehicle / time_scale,
            f"the takeoff to {alt_m:.1f} m",
        )
        if left_guided(link.telemetry):
            raise LinkError(f"the vehicle left GUIDED during the takeoff (now {link.telemetry.mode_name})")
    except (LinkError, asyncio.CancelledError) as exc:
        outcome = await asyncio.shield(
            abandon_start(link, commanded, str(exc) or "interrupted", settings.join_min_height_m)
        )
        if isinstance(exc, asyncio.CancelledError):
            raise
        raise FlightAborted(f"{exc}; vehicle {outcome}") from None
    return plan
