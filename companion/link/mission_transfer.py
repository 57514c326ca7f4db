"""Mission, fence and rally transfer (``VehicleLink.missions``) with MAVSDK's MissionRaw
(MISSION_ITEM_INT; ArduPilot's home at mission seq 0), like a ground station: an upload is all
or nothing (a failed list restores the lists already replaced from a download taken before),
and an empty list is cleared with MISSION_CLEAR_ALL confirmed by MISSION_ACK (MissionRaw
refuses to upload an empty list).
"""

from __future__ import annotations

import asyncio
import json
import logging

from companion.errors import LinkError, MissionError
from companion.link.ports import MessageSource
from companion.link.session import LinkSession
from companion.mission.model import MissionPlan
from companion.mission.raw import RawItem, fence_to_raw, mission_to_raw, rally_to_raw, raw_to_plan

log = logging.getLogger(__name__)


def to_mavsdk_item(raw: RawItem):
    """``RawItem`` -> ``mavsdk.plugins.mission_raw.MissionItem``."""
    from mavsdk.plugins.mission_raw import MissionItem

    return MissionItem(
        raw.seq,
        raw.frame,
        raw.command,
        raw.current,
        raw.autocontinue,
        raw.param1,
        raw.param2,
        raw.param3,
        raw.param4,
        raw.x,
        raw.y,
        raw.z,
        raw.mission_type,
    )


def from_mavsdk_item(item) -> RawItem:
    """``mavsdk.plugins.mission_raw.MissionItem`` -> ``RawItem``."""
    return RawItem(
        int(item.seq),
        int(item.frame),
        int(item.command),
        int(item.current),
        int(item.autocontinue),
        float(item.param1),
        float(item.param2),
        float(item.param3),
        float(item.param4),
        int(item.x),
        int(item.y),
        float(item.z),
        int(item.mission_type),
    )


class MissionTransfer:
    """The mission transfers of the link (``VehicleLink.missions``), one at a time.

    Parameters
    ----------
    session : LinkSession
        The connection: MAVSDK's MissionRaw plugin, MavlinkDirect (MISSION_CLEAR_ALL), the target.
    source : MessageSource
        Received messages (MISSION_ACK).
    """

    def __init__(self, session: LinkSession, source: MessageSource) -> None:
        self._session = session
        self._source = source
        self._lock = asyncio.Lock()

    async def download_raw(self) -> tuple[list[RawItem], list[RawItem], list[RawItem]]:
        """Download the mission, fence and rally lists as ``RawItem`` lists."""
        from mavsdk.plugins.mission_raw import MissionRawError, MissionRawResult

        self._session.require_connected()
        plugin = self._session.mission
        lists = []
        for name, fetch in (
            ("mission", plugin.download_mission),
            ("fence", plugin.download_geofence),
            ("rally", plugin.download_rallypoints),
        ):
            try:
                items = await fetch()
            except MissionRawError as exc:
                if exc.result == MissionRawResult.NO_MISSION_AVAILABLE:
                    items = []
                else:
                    raise LinkError(f"{name} download failed: {exc.result.name}") from None
            lists.append([from_mavsdk_item(i) for i in (items or [])])
        return lists[0], lists[1], lists[2]

    async def download_plan(self) -> MissionPlan:
        """Download mission + fence + rally as a ``MissionPlan`` (seq 0 = home, ArduPilot)."""
        async with self._lock:
            mission, fence, rally = await self.download_raw()
        try:
            return raw_to_plan(mission, fence, rally)
        except MissionError as exc:
            raise LinkError(f"the vehicle's lists cannot be read: {exc}") from None

    async def upload_plan(self, plan: MissionPlan, home_lla=None) -> None:
        """Upload mission, fence and rally like a ground station; all or nothing.

        The plan is validated first (a bad plan uploads nothing). The vehicle replaces each
        list only when its transfer completes; if a later list fails, the lists already replaced
        are restored from a download taken before the upload.

        Raises
        ------
        MissionError
            The plan is invalid (nothing sent).
        LinkError
            A transfer failed (the previous lists are restored when possible).
        """
        plan.validate()
        lists = (
            ("mission", mission_to_raw(plan, home_lla)),
            ("fence", fence_to_raw(plan)),
            ("rally", rally_to_raw(plan)),
        )
        async with self._lock:
            backup = await self.download_raw()
            done: list[int] = []
            for k, (name, raw) in enumerate(lists):
                try:
                    await self._upload_list(name, raw)
                except LinkError as exc:
                    await self._restore(backup, done)
                    outcome = "the lists already replaced were restored" if done else "nothing was changed"
                    raise LinkError(f"{exc}; {outcome}") from None
                done.append(k)
        log.info(
            "uploaded %d mission items, %d fence items, %d rally points",
            len(plan.items),
            len(lists[1][1]),
            len(plan.rally),
        )

    async def _upload_list(self, name: str, raw: list[RawItem]) -> None:
        from mavsdk.plugins.mission_raw import MissionRawError

        plugin = self._session.mission
        upload = {
            "mission": plugin.upload_mission,
            "fence": plugin.upload_geofence,
            "rally": plugin.upload_rally_points,
        }[name]
        try:
            if raw:
                await upload([to_mavsdk_item(r) for r in raw])
            else:
                await self._clear_list(name)
        except MissionRawError as exc:
            raise LinkError(f"{name} upload failed: {exc.result.name}") from None

    async def clear_plan(self) -> None:
        """Clear the vehicle's mission, fence and rally lists (each confirmed by MISSION_ACK)."""
        self._session.require_connected()
        async with self._lock:
            for name in ("mission", "fence", "rally"):
                await self._clear_list(name)

    async def _clear_list(self, name: str, attempts: int = 3, timeout_s: float = 1.5) -> None:
        """Clear one list: MISSION_CLEAR_ALL for its mission type, confirmed by MISSION_ACK.

        (MAVSDK's MissionRaw refuses to upload an empty list, so clearing is done directly.)
        """
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        session = self._session
        mission_type = {"mission": 0, "fence": 1, "rally": 2}[name]
        fields = {
            "target_system": session.target_system,
            "target_component": session.target_component,
            "mission_type": mission_type,
        }
        message = MavlinkMessage(
            "MISSION_CLEAR_ALL", 0, 0, session.target_system, session.target_component, json.dumps(fields)
        )

        async def wait_ack() -> int:
            async for ack in self._source.messages("MISSION_ACK"):
                if session.from_vehicle(ack) and int(ack.get("mission_type", 0)) == mission_type:
                    return int(ack.get("type", -1))
            return -1

        for _ in range(attempts):
            waiter = asyncio.ensure_future(wait_ack())
            await asyncio.sleep(0)  # subscribed before the request goes out
            session.direct.send_message(message)
            try:
                result = await asyncio.wait_for(waiter, timeout_s)
            except TimeoutError:
                continue
            if result != 0:
                raise LinkError(f"{name} clear refused: MAV_MISSION_RESULT {result}")
            return
        raise LinkError(f"{name} clear: no MISSION_ACK after {attempts} attempts")

    async def _restore(self, backup, done: list[int]) -> None:
        names = ("mission", "fence", "rally")
        for k in done:
            try:
                await self._upload_list(names[k], backup[k])
            except LinkError as exc:
                log.error("could not restore the previous %s: %s", names[k], exc)
