"""The MAVLink parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ and PARAM_SET.

As ArduPilot's ``GCS_Param``: the table (:class:`sim_vehicle.params.ParameterTable`) maps each
parameter to a setting; a PARAM_SET that the table accepts replaces the settings tree and is
applied at once (by the ``on_change`` callback), one it refuses is shown as STATUSTEXT, and the
resulting PARAM_VALUE goes to every link either way.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim_vehicle.config import VehicleSettings
from sim_vehicle.mavlink.endpoint import Address, Endpoint
from sim_vehicle.params import ParameterTable

log = logging.getLogger(__name__)


def param_name(raw: Any) -> str:
    """The name of a ``param_id`` field (16 bytes, NUL-padded unless the name fills them)."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return str(raw).split("\x00", 1)[0]


class ParamProtocol:
    """Answers the parameter messages from one :class:`ParameterTable`.

    Parameters
    ----------
    params : ParameterTable
        The parameters and the settings tree they read and write.
    endpoint : Endpoint
        Where PARAM_VALUE and STATUSTEXT go.
    on_change : callable
        ``on_change(old, new)`` after a PARAM_SET replaced the settings tree.
    """

    def __init__(
        self, params: ParameterTable, endpoint: Endpoint, on_change: Callable[[VehicleSettings, VehicleSettings], None]
    ) -> None:
        self.params = params
        self.endpoint = endpoint
        self._on_change = on_change

    def send_value(self, index: int, address: Address | None = None) -> None:
        """PARAM_VALUE of parameter ``index`` to ``address`` (None: every link)."""
        spec = self.params.specs[index]
        self.endpoint.send(
            self.endpoint.mav.param_value_encode(
                spec.name.encode(), self.params.value(spec), spec.param_type, len(self.params), index
            ),
            address,
        )

    def on_param_request_list(self, msg: Any, address: Address) -> None:
        for index in range(len(self.params)):
            self.send_value(index, address)

    def on_param_request_read(self, msg: Any, address: Address) -> None:
        name = param_name(msg.param_id)
        index = msg.param_index if msg.param_index >= 0 else self.params.index(name)
        if not 0 <= index < len(self.params):
            log.info("PARAM_REQUEST_READ %r (index %d): no such parameter", name, msg.param_index)
            return
        self.send_value(index, address)

    def on_param_set(self, msg: Any, address: Address) -> None:
        name = param_name(msg.param_id)
        index = self.params.index(name)
        if index < 0:
            log.warning("PARAM_SET %r: no such parameter; ignored", name)
            return
        old = self.params.settings
        ok, reason = self.params.set(name, float(msg.param_value))
        if ok:
            self._on_change(old, self.params.settings)
        else:
            self.endpoint.statustext(mavlink.MAV_SEVERITY_WARNING, f"{name} refused")
        self.send_value(index)  # everyone sees the (new or unchanged) value
