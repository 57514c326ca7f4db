"""zenoh security configuration of the threat bus: mutual TLS and access control (issue 11).

Who may put a threat is decided by zenoh itself, not by a field of the payload:

- every link is ``tls/`` with mutual TLS (``transport.link.tls.enable_mtls``): a session without
  a certificate signed by the deployment's CA cannot connect at all;
- the companion's ``access_control`` (``default_permission: deny``) matches each connected
  session by its certificate common name (``subjects[].cert_common_names``) and lets a threat
  source ``S`` put and delete only on ``uav/<sysid>/threats/S/*``. The key's ``S`` segment is
  therefore authenticated: the companion records it as the threat's ``source``;
- the companion's ``status``, ``events`` and ``path`` go only to the sources and to the
  observers (read-only identities); any other identity, even one signed by the CA, sees nothing
  and its puts are dropped by the companion's zenoh before they reach the subscriber.

This module builds those configurations (plain dicts, written as JSON, which is JSON5) and
loads one for a ``ThreatBus`` (``load_config``), checking the files it names.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

from companion.errors import ConfigError

__all__ = [
    "SecurityInfo",
    "access_control",
    "companion_config",
    "peer_config",
    "load_config",
    "write_config",
    "TELEMETRY_LEAVES",
    "TLS_KEYS",
]

log = logging.getLogger(__name__)

#: What the companion publishes; subscribers must declare exactly these keys (the ACL does not
#: match a wider subscription such as ``uav/<sysid>/**``).
TELEMETRY_LEAVES = ("status", "events", "path")
#: File entries of ``transport.link.tls`` that name a file.
TLS_KEYS = (
    "root_ca_certificate",
    "listen_private_key",
    "listen_certificate",
    "connect_private_key",
    "connect_certificate",
)


def _base(mode: str, listen, connect) -> dict:
    return {
        "mode": mode,
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "listen": {"endpoints": list(listen)},
        "connect": {"endpoints": list(connect)},
    }


def access_control(sysid: int, sources, observers=()) -> dict:
    """The companion's ``access_control`` block.

    Parameters
    ----------
    sysid : int
        Key prefix ``uav/<sysid>``.
    sources : sequence of str
        Common names of the threat sources: each may put/delete ``uav/<sysid>/threats/<name>/*``,
        list the threats (query ``uav/<sysid>/threats/**``) and read status, events and path.
    observers : sequence of str
        Common names that may only read status, events and path.

    Returns
    -------
    dict
        ``enabled``, ``default_permission`` (``deny``), ``rules``, ``subjects``, ``policies``.
    """
    sources, observers = list(sources), list(observers)
    if not sources:
        raise ConfigError("access_control: give at least one threat source")
    overlap = sorted(set(sources) & set(observers))
    if overlap:
        raise ConfigError(f"access_control: {overlap} named both as source and as observer")
    prefix = f"uav/{sysid}"
    telemetry = [f"{prefix}/{leaf}" for leaf in TELEMETRY_LEAVES]
    rules = [
        {
            "id": "threats-declare",
            "permission": "allow",
            "flows": ["egress"],
            "messages": ["declare_subscriber", "declare_queryable"],
            "key_exprs": [f"{prefix}/threats/**"],
        },
        {
            "id": "threats-list",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": ["query"],
            "key_exprs": [f"{prefix}/threats/**"],
        },
        {
            "id": "threats-list-reply",
            "permission": "allow",
            "flows": ["egress"],
            "messages": ["reply"],
            "key_exprs": [f"{prefix}/threats/**"],
        },
        {
            "id": "telemetry-subscribe",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": ["declare_subscriber"],
            "key_exprs": telemetry,
        },
        {
            "id": "telemetry-out",
            "permission": "allow",
            "flows": ["egress"],
            "messages": ["put"],
            "key_exprs": telemetry,
        },
    ]
    subjects = [
        {"id": "sources", "cert_common_names": sources},
        {"id": "readers", "cert_common_names": sources + observers},
    ]
    policies = [
        {"id": "sources", "rules": ["threats-declare", "threats-list", "threats-list-reply"], "subjects": ["sources"]},
        {"id": "readers", "rules": ["telemetry-subscribe", "telemetry-out"], "subjects": ["readers"]},
    ]
    for name in sources:
        rules.append(
            {
                "id": f"put-{name}",
                "permission": "allow",
                "flows": ["ingress"],
                "messages": ["put", "delete"],
                "key_exprs": [f"{prefix}/threats/{name}/*"],
            }
        )
        subjects.append({"id": f"source-{name}", "cert_common_names": [name]})
        policies.append({"id": f"source-{name}", "rules": [f"put-{name}"], "subjects": [f"source-{name}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def companion_config(*, ca_cert, key, cert, listen, sysid: int, sources, observers=(), connect=()) -> dict:
    """The companion's zenoh configuration: ``tls/`` listen endpoints with mutual TLS and the ACL.

    Parameters
    ----------
    ca_cert, key, cert : str or Path
        The CA certificate and the companion's key and certificate (paths written as given).
    listen, connect : sequence of str
        ``tls/HOST:PORT`` endpoints.
    sysid, sources, observers
        See ``access_control``.
    """
    _check_tls_endpoints(listen, "listen")
    _check_tls_endpoints(connect, "connect")
    cfg = _base("peer", listen, connect)
    cfg["transport"] = {
        "link": {
            "tls": {
                "root_ca_certificate": str(ca_cert),
                "listen_private_key": str(key),
                "listen_certificate": str(cert),
                "connect_private_key": str(key),
                "connect_certificate": str(cert),
                "enable_mtls": True,
                "verify_name_on_connect": True,
            }
        }
    }
    cfg["access_control"] = access_control(sysid, sources, observers)
    return cfg


def peer_config(*, ca_cert, key, cert, connect) -> dict:
    """A threat source's or observer's configuration: connects to the companion with its certificate."""
    _check_tls_endpoints(connect, "connect")
    if not connect:
        raise ConfigError("connect: a source or observer needs the companion's tls/ endpoint")
    cfg = _base("peer", (), connect)
    cfg["transport"] = {
        "link": {
            "tls": {
                "root_ca_certificate": str(ca_cert),
                "connect_private_key": str(key),
                "connect_certificate": str(cert),
                "enable_mtls": True,
                "verify_name_on_connect": True,
            }
        }
    }
    return cfg


def _check_tls_endpoints(endpoints, name: str) -> None:
    for i, ep in enumerate(endpoints):
        if not isinstance(ep, str) or not ep.startswith("tls/") or ":" not in ep[4:]:
            raise ConfigError(f"{name}[{i}]: expected a tls/HOST:PORT endpoint (mutual TLS), got {ep!r}")


@dataclass(frozen=True)
class SecurityInfo:
    """What a loaded zenoh configuration file says about security.

    Attributes
    ----------
    path : str
        The file.
    acl_enabled : bool
        ``access_control.enabled``: threats must then come on ``threats/<source>/<id>``.
    mtls : bool
        ``transport.link.tls.enable_mtls``.
    identity : str or None
        Common name of the session's own certificate (connect, else listen certificate), if any.
    mode : str
        ``peer``, ``client`` or ``router``.
    """

    path: str
    acl_enabled: bool
    mtls: bool
    identity: str | None
    mode: str


def _get(cfg, key: str):
    try:
        text = cfg.get_json(key)
    except Exception:  # an absent key: zenoh raises
        return None
    return json.loads(text) if text else None


def load_config(path, *, listen=None, connect=None):
    """Load a zenoh configuration file (JSON5) for a ``ThreatBus``.

    Parameters
    ----------
    path : str or Path
        The file (``companion keys init`` writes one per identity).
    listen, connect : sequence of str, optional
        Replace the file's endpoints when given.

    Returns
    -------
    (zenoh.Config, SecurityInfo)

    Raises
    ------
    ConfigError
        Naming the file: missing, unreadable, not a valid zenoh configuration, or naming a
        certificate or key file that does not exist.
    """
    import zenoh

    from companion.security.keys import common_name, load_certificate

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"--zenoh-config {p}: no such file")
    try:
        cfg = zenoh.Config.from_file(str(p))
    except Exception as exc:
        raise ConfigError(f"--zenoh-config {p}: not a valid zenoh configuration: {exc}") from None
    for name in TLS_KEYS:
        file = _get(cfg, f"transport/link/tls/{name}")
        if file and not Path(file).is_file():
            raise ConfigError(f"--zenoh-config {p}: transport.link.tls.{name}: no such file {file!r}")
    try:
        if listen is not None:
            cfg.insert_json5("listen/endpoints", json.dumps(list(listen)))
        if connect is not None:
            cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
    except Exception as exc:
        raise ConfigError(f"--zenoh-config {p}: endpoints: {exc}") from None
    cert_file = _get(cfg, "transport/link/tls/connect_certificate") or _get(
        cfg, "transport/link/tls/listen_certificate"
    )
    identity = common_name(load_certificate(cert_file)) if cert_file else None
    info = SecurityInfo(
        str(p),
        bool(_get(cfg, "access_control/enabled")),
        bool(_get(cfg, "transport/link/tls/enable_mtls")),
        identity,
        str(_get(cfg, "mode") or "peer"),
    )
    if info.acl_enabled and not info.mtls:
        log.warning(
            "%s: access control without mutual TLS: cert_common_names cannot match; "
            "only interface or username subjects apply",
            p,
        )
    return cfg, info


def write_config(cfg: dict, path) -> Path:
    """Write ``cfg`` as indented JSON (valid JSON5) with a header comment."""
    path = Path(path)
    path.write_text(
        "// zenoh configuration written by `companion keys init` (JSON5)\n" + json.dumps(cfg, indent=2) + "\n"
    )
    return path
