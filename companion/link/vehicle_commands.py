"""Commands to the vehicle (``VehicleLink.commands``): COMMAND_LONG through MavlinkDirect, each
checked against its COMMAND_ACK (a refusal is ``VehicleRefused``), and parameters read with
PARAM_REQUEST_READ.

DO_SET_MODE with ArduCopter custom modes (GUIDED 4 ...), arm/disarm, takeoff, land, RTL,
DO_AUX_FUNCTION (the motor interlock), REQUEST_MESSAGE. MAVSDK's ``send_command`` blocks until
the ack or its own retries give up, so it runs in an executor; each such call is kept in
``_in_flight`` until it ends, and ``VehicleLink.aclose`` waits for them (``wait_in_flight``)
before it releases MAVSDK (a call left blocked after MAVSDK was released would block for good).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from collections.abc import Callable

from companion.errors import LinkError, VehicleRefused
from companion.link.ports import MessageSender, MessageSource, StatusTextLog
from companion.link.session import LinkSession
from companion.link.telemetry import Telemetry
from companion.link.waits import wait_for
from heli_common.ardupilot_ids import FORCE_DISARM_MAGIC
from heli_common.mavlink_ids import COPTER_MODE_NAMES, COPTER_MODES, MAV_RESULT_NAMES, mavlink

log = logging.getLogger(__name__)

# MAVLink numbers: from pymavlink (``heli_common.mavlink_ids``)
MAV_CMD_NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
MAV_CMD_NAV_LAND = mavlink.MAV_CMD_NAV_LAND
MAV_CMD_NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
MAV_CMD_DO_SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
MAV_CMD_COMPONENT_ARM_DISARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
MAV_CMD_REQUEST_MESSAGE = mavlink.MAV_CMD_REQUEST_MESSAGE
MAV_CMD_DO_AUX_FUNCTION = mavlink.MAV_CMD_DO_AUX_FUNCTION
MAVLINK_MSG_ID_HOME_POSITION = mavlink.MAVLINK_MSG_ID_HOME_POSITION
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
#: COMPONENT_ARM_DISARM param2 that disarms even in the air (ArduPilot).


def mode_number(mode) -> int:
    """ArduCopter mode number from a name (``"GUIDED"``) or a number."""
    if isinstance(mode, str):
        try:
            return COPTER_MODES[mode.upper()]
        except KeyError:
            raise LinkError(f"unknown flight mode {mode!r}; known: {', '.join(COPTER_MODES)}") from None
    return int(mode)


class VehicleCommands:
    """The commands and parameter reads of the link (``VehicleLink.commands``).

    Parameters
    ----------
    session : LinkSession
        The connection: MavlinkDirect (``send_command``) and the target.
    source : MessageSource
        Received messages (PARAM_VALUE).
    sender : MessageSender
        Sends PARAM_REQUEST_READ.
    telemetry : callable() -> Telemetry
        The latest snapshot: a mode or arming command waits to see its effect.
    texts : StatusTextLog
        The vehicle's STATUSTEXTs, quoted in a refusal.
    """

    def __init__(
        self,
        session: LinkSession,
        source: MessageSource,
        sender: MessageSender,
        telemetry: Callable[[], Telemetry],
        texts: StatusTextLog,
    ) -> None:
        self._session = session
        self._source = source
        self._sender = sender
        self._telemetry = telemetry
        self._texts = texts
        self._lock = asyncio.Lock()  # one MAVSDK command call at a time
        self._in_flight: set[asyncio.Future] = set()  # MAVSDK command calls still running

    def _command_message(self, command: int, params):
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        # MavlinkDirect takes strict JSON, which has no NaN: unset parameters travel as 0
        values = [float(p) if math.isfinite(float(p)) else 0.0 for p in params]
        values += [0.0] * (7 - len(values))
        target = self._session
        fields = {
            "target_system": target.target_system,
            "target_component": target.target_component,
            "command": int(command),
            "confirmation": 0,
        }
        fields.update({f"param{k + 1}": v for k, v in enumerate(values)})
        return MavlinkMessage("COMMAND_LONG", 0, 0, target.target_system, target.target_component, json.dumps(fields))

    async def command_result(
        self, command: int, params=(), *, what: str | None = None, timeout_s: float = 10.0
    ) -> int | None:
        """Send COMMAND_LONG and return the MAV_RESULT of its COMMAND_ACK (None: no final ack
        within ``timeout_s``). Never raises for a refusal: see ``command_long``."""
        from mavsdk.plugins.mavlink_direct import MavlinkDirectError

        self._session.require_connected()
        message = self._command_message(command, params)
        label = what or f"command {command}"
        async with self._lock:
            # MAVSDK's blocking call runs in a thread we keep track of: releasing MAVSDK while it
            # waits would leave that thread blocked for good (see ``aclose``)
            call = asyncio.get_running_loop().run_in_executor(None, self._session.direct.send_command, message)
            self._in_flight.add(call)
            call.add_done_callback(self._command_call_done)
            try:
                ack = await asyncio.wait_for(asyncio.shield(call), timeout_s)
            except TimeoutError:
                log.info("%s: no COMMAND_ACK within %g s", label, timeout_s)
                return None
            except MavlinkDirectError as exc:
                log.info("%s: no COMMAND_ACK (%s)", label, exc.result.name)
                return None
        try:
            result = int(json.loads(ack.fields_json).get("result", -1))
        except (json.JSONDecodeError, TypeError, ValueError, AttributeError):
            log.info("%s: unreadable COMMAND_ACK", label)
            return None
        log.log(logging.INFO if result == 0 else logging.DEBUG, "%s: %s", label, MAV_RESULT_NAMES.get(result, result))
        return result

    async def wait_in_flight(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for the MAVSDK command calls still running (MAVSDK ends each
        within its own retries, a few seconds)."""
        if self._in_flight:
            await asyncio.wait(set(self._in_flight), timeout=timeout_s)

    def _command_call_done(self, call: asyncio.Future) -> None:
        self._in_flight.discard(call)
        if not call.cancelled():
            call.exception()  # retrieved: a late failure after our timeout is no error

    async def command_long(self, command: int, params=(), *, what: str | None = None, timeout_s: float = 10.0) -> None:
        """Send COMMAND_LONG and check its COMMAND_ACK.

        Parameters
        ----------
        command : int
            MAV_CMD.
        params : sequence of up to 7 floats
            param1..param7 (missing ones are 0).

        Raises
        ------
        LinkError
            No final ack (naming ``what``).
        VehicleRefused
            The vehicle answered anything but ACCEPTED (naming the MAV_RESULT and the
            vehicle's last STATUSTEXT, e.g. ``PreArm: Motor Interlock Enabled``).
        """
        label = what or f"command {command}"
        sent_t = time.monotonic()
        result = await self.command_result(command, params, what=label, timeout_s=timeout_s)
        if result is None:
            raise LinkError(f"{label}: no COMMAND_ACK within {timeout_s:g} s")
        if result != 0:
            raise VehicleRefused(self.refusal_text(label, result, sent_t), result)

    def refusal_text(self, label: str, result: int | None, since_monotonic_s: float) -> str:
        """``"<label> refused by the vehicle: FAILED (PreArm: ...)"``: the MAV_RESULT and the
        vehicle's most telling STATUSTEXT since ``since_monotonic_s`` (a PreArm/Arm line first)."""
        texts = self._texts.statustexts_since(since_monotonic_s - 0.5)
        telling = [t for t in texts if t.startswith(("PreArm", "Arm"))] or texts
        why = f" ({telling[-1]})" if telling else ""
        name = "no answer" if result is None else MAV_RESULT_NAMES.get(result, result)
        return f"{label} refused by the vehicle: {name}{why}"

    async def set_mode(self, mode) -> None:
        """Switch to an ArduCopter mode (name or number) with DO_SET_MODE and wait to see it."""
        number = mode_number(mode)
        name = COPTER_MODE_NAMES.get(number, str(number))
        await self.command_long(
            MAV_CMD_DO_SET_MODE, (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, number), what=f"set mode {name}"
        )
        await wait_for(self._telemetry, lambda t: t.mode == number, 5.0, f"mode {name} in the heartbeat")

    async def arm(self) -> None:
        """Arm (COMPONENT_ARM_DISARM 1); ``LinkError`` if the vehicle refuses."""
        await self.command_long(MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), what="arm")
        await wait_for(self._telemetry, lambda t: bool(t.armed), 5.0, "armed state")

    async def disarm(self, force: bool = False) -> None:
        """Disarm (``force``: even in the air, ArduPilot's 21196 magic)."""
        await self.command_long(
            MAV_CMD_COMPONENT_ARM_DISARM, (0.0, FORCE_DISARM_MAGIC if force else 0.0), what="disarm"
        )

    async def takeoff(self, alt_m: float) -> None:
        """GUIDED takeoff to ``alt_m`` above home (NAV_TAKEOFF param7); vehicle must be armed."""
        if not (math.isfinite(alt_m) and alt_m > 0.0):
            raise LinkError(f"takeoff altitude alt_m must be > 0, got {alt_m}")
        await self.command_long(MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, float(alt_m)), what=f"takeoff to {alt_m:g} m")

    async def land(self) -> None:
        """Land here (NAV_LAND)."""
        await self.command_long(MAV_CMD_NAV_LAND, (), what="land")

    async def return_to_launch(self) -> None:
        """Return to launch (NAV_RETURN_TO_LAUNCH)."""
        await self.command_long(MAV_CMD_NAV_RETURN_TO_LAUNCH, (), what="return to launch")

    async def aux_function(self, function: int, switch: int, *, timeout_s: float = 3.0) -> int | None:
        """MAV_CMD_DO_AUX_FUNCTION (an RC switch function, e.g. 32 MOTOR_INTERLOCK) at switch
        position ``switch`` (0 low, 1 middle, 2 high); returns the MAV_RESULT (None: no ack)."""
        return await self.command_result(
            MAV_CMD_DO_AUX_FUNCTION,
            (function, switch),
            what=f"aux function {function} switch {switch}",
            timeout_s=timeout_s,
        )

    async def read_params(self, names, timeout_s: float = 2.0) -> dict[str, float]:
        """Read parameters with PARAM_REQUEST_READ (sent twice, all at once).

        Returns
        -------
        dict
            Name -> value (ArduPilot encoding: the value as a float) of those the vehicle
            answered within ``timeout_s``; a parameter the vehicle does not have is absent.
        """
        session = self._session
        session.require_connected()
        wanted = {str(n) for n in names}
        got: dict[str, float] = {}

        async def collect() -> None:
            async for fields in self._source.messages("PARAM_VALUE"):
                name = str(fields.get("param_id", "")).rstrip("\x00")
                if session.from_vehicle(fields) and name in wanted:
                    got[name] = float(fields.get("param_value", math.nan))
                    if len(got) == len(wanted):
                        return

        waiter = asyncio.ensure_future(collect())
        await asyncio.sleep(0)  # subscribed before the requests go out
        try:
            for _attempt in range(2):
                for name in sorted(wanted - set(got)):
                    self._sender.send_message(
                        "PARAM_REQUEST_READ",
                        {
                            "target_system": session.target_system,
                            "target_component": session.target_component,
                            "param_id": name,
                            "param_index": -1,
                        },
                    )
                done, _ = await asyncio.wait({waiter}, timeout=timeout_s / 2.0)
                if done:
                    break
        finally:
            waiter.cancel()
            await asyncio.gather(waiter, return_exceptions=True)
        log.info(
            "parameters read: %s%s",
            ", ".join(f"{k}={v:g}" for k, v in sorted(got.items())) or "none",
            "" if len(got) == len(wanted) else f"; not on the vehicle: {', '.join(sorted(wanted - set(got)))}",
        )
        return got

    async def request_home(self) -> None:
        """Ask for HOME_POSITION (REQUEST_MESSAGE 242); the answer updates the telemetry."""
        await self.command_long(
            MAV_CMD_REQUEST_MESSAGE, (MAVLINK_MSG_ID_HOME_POSITION,), what="request HOME_POSITION", timeout_s=3.0
        )
