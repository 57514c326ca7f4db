"""The STATUSTEXT that tells the ground stations about a threat decision (DESIGN 7.5): short
(MAVLink's 50 characters), the latency kept, a WARNING for an evasion, a hold or a rejected
threat."""

from __future__ import annotations

#: STATUSTEXT carries at most 50 characters.
STATUSTEXT_MAX_CHARS = 50
#: Decisions told to the ground stations as a WARNING (the others as a NOTICE).
WARNING_KINDS = frozenset({"evade", "hold", "rejected"})


def statustext_for(kind: str, label: str, threat_id: str | None, latency_ms: float | None) -> tuple[str, str]:
    """The STATUSTEXT of one published decision and its severity.

    Parameters
    ----------
    kind : str
        The decision's kind (``evade``, ``replan``, ``rejected`` ...).
    label : str
        Its short label, e.g. ``"evade left"`` (the kind when the manager gives none).
    threat_id : str or None
        The threat that caused it; None for a plan back to the mission.
    latency_ms : float or None
        Trigger to first setpoint (ms), when measured.

    Returns
    -------
    (str, str)
        The text, at most ``STATUSTEXT_MAX_CHARS`` characters (the label is shortened first,
        the latency kept), e.g. ``"AVOID m1: evade left, 31 ms"``; and the severity name,
        ``"WARNING"`` for an evasion, a hold or a rejected threat, else ``"NOTICE"``.

    Examples
    --------
    >>> statustext_for("replan", "replan", "p1", 140.2)
    ('AVOID p1: replan, 140 ms', 'NOTICE')
    """
    if kind == "rejected":
        head = f"THREAT {threat_id or '?'} rejected"
    else:
        head = f"AVOID {threat_id}" if threat_id else "RESUME"
    tail = "" if latency_ms is None else f", {latency_ms:.0f} ms"
    text = f"{head}: {label}" if label else head
    text = text[: STATUSTEXT_MAX_CHARS - len(tail)] + tail
    return text, "WARNING" if kind in WARNING_KINDS else "NOTICE"
