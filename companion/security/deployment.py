"""``companion keys init``: the certificates and zenoh configurations of a small deployment.

Layout of the directory (every path inside the configurations is absolute)::

    ca.key  ca.pem                 the CA (keep ca.key offline once the identities are issued)
    <companion>.key .pem .json5    the companion: listens on tls/ with mutual TLS and the ACL
    <source>.key .pem .json5       each threat source: connects with its certificate; may put
                                   and delete uav/<sysid>/threats/<source>/<id> only
    <observer>.key .pem .json5     each observer: may read status, events and path only
    mavlink.key                    the MAVLink 2 signing key (a passphrase, as MAVProxy's
                                   ``signing setup``); the settings' ``link.signing_key_file``

Private keys are written with mode 0600. The default directory (``default_keys_dir``) is the
user's configuration directory, outside any repository; an explicit directory may hold other
files, but a file of the deployment that exists already is overwritten only with ``force``.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

from companion.security import keys
from companion.security.paths import default_keys_dir
from companion.threats.transport import access

__all__ = ["Deployment", "default_keys_dir", "deployment_files", "init_deployment"]

log = logging.getLogger(__name__)


def deployment_files(directory, names, mavlink_key: bool = True) -> list:
    """Every file ``init_deployment`` writes in ``directory`` for the identities ``names``.

    Parameters
    ----------
    directory : str or Path
        The deployment's directory.
    names : sequence of str
        The companion's, the sources' and the observers' names.
    mavlink_key : bool
        With the MAVLink signing key (``mavlink.key``).

    Returns
    -------
    list of Path
        ``ca.key``, ``ca.pem``, then ``<name>.key``, ``.pem`` and ``.json5`` of each name, then
        ``mavlink.key``.
    """
    d = Path(directory)
    files = [d / "ca.key", d / "ca.pem", *(d / f"{n}{ext}" for n in names for ext in (".key", ".pem", ".json5"))]
    return files + ([d / MAVLINK_KEY] if mavlink_key else [])


def _check_overwrite(d: Path, names, mavlink_key: bool, force: bool) -> None:
    """Refuse, naming them, the deployment's files that exist already (unless ``force``)."""
    existing = [p.name for p in deployment_files(d, names, mavlink_key) if p.exists()]
    if existing and not force:
        raise keys.KeyMaterialError(
            f"{d}: {', '.join(existing)} exist already (a deployment's keys?); "
            f"use --force to overwrite them (a new CA: every identity must then be "
            f"redeployed), or choose another directory"
        )


def _make_directory(d: Path) -> None:
    """Create ``d`` (and its parents); one made here is readable by its owner only (0700)."""
    if d.exists() and not d.is_dir():
        raise keys.KeyMaterialError(f"{d}: exists and is not a directory")
    try:
        d.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError as exc:
        raise keys.KeyMaterialError(f"{d}: cannot create the directory: {exc.strerror or exc}") from None


@dataclass
class Deployment:
    """What ``init_deployment`` wrote (paths), by identity name."""

    directory: Path
    ca_cert: Path
    ca_key: Path
    companion: str
    sources: list
    observers: list
    certs: dict = field(default_factory=dict)
    keys: dict = field(default_factory=dict)
    configs: dict = field(default_factory=dict)
    mavlink_key: Path | None = None


MAVLINK_KEY = "mavlink.key"
"""The MAVLink 2 signing key's file name in a deployment (``deploy/companion.toml`` names it)."""


def _hosts_of(endpoints) -> list:
    out = []
    for ep in endpoints:
        m = re.match(r"^tls/\[?([^\]]+?)\]?:\d+$", ep)
        if m and m.group(1) not in ("0.0.0.0", "::"):
            out.append(m.group(1))
    return out


def _write_mavlink_key(path: Path) -> Path:
    """A new MAVLink 2 signing key file (``mavlink_signing.new_passphrase``, mode 0600)."""
    from mavlink_signing import SigningKeyError, new_passphrase, write_key_file

    try:
        return write_key_file(path, new_passphrase())
    except SigningKeyError as exc:
        raise keys.KeyMaterialError(str(exc)) from None


def init_deployment(
    directory,
    *,
    sysid: int = 1,
    companion: str = "companion",
    sources=("source1",),
    observers=(),
    listen=("tls/0.0.0.0:7447",),
    connect=("tls/localhost:7447",),
    hosts=(),
    days: int = keys.DEFAULT_DAYS,
    mavlink_key: bool = True,
    force: bool = False,
) -> Deployment:
    """Create the CA, the identities and their zenoh configurations in ``directory``.

    Parameters
    ----------
    directory : str or Path
        Created if needed (mode 0700). It may hold other files; the deployment's own files
        (``deployment_files``) that exist already are refused unless ``force``.
    sysid : int
        Vehicle system id of the keys in the ACL (``uav/<sysid>/...``).
    companion : str
        Common name of the companion.
    sources, observers : sequence of str
        Common names of the threat sources (at least one) and of the read-only observers.
    listen : sequence of str
        The companion's ``tls/`` endpoints.
    connect : sequence of str
        The endpoints the sources and observers connect to (the companion's address as they
        reach it; its host names are put in the companion's certificate).
    hosts : sequence of str
        More host names or IP addresses for the companion's certificate.
    days : int
        Validity of the identities (days).
    mavlink_key : bool
        Also write ``mavlink.key``, a new MAVLink 2 signing key (a random passphrase, mode 0600).
    force : bool
        Overwrite the files of an existing deployment.

    Returns
    -------
    Deployment
        The paths written.

    Raises
    ------
    companion.security.keys.KeyMaterialError
        A bad or repeated name, a file of the deployment that exists without ``force`` (the
        message names them), a file that cannot be written.
    """
    if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
        raise keys.KeyMaterialError(f"--sysid: must be an integer in 1..255, got {sysid!r}")
    if not isinstance(days, int) or days < 1:
        raise keys.KeyMaterialError(f"--days: must be a positive integer, got {days!r}")
    sources, observers = list(sources), list(observers)
    if not sources:
        raise keys.KeyMaterialError("--source: give at least one threat source name")
    keys.check_name(companion, "--companion")
    for s in sources:
        keys.check_name(s, "--source")
    for o in observers:
        keys.check_name(o, "--observer")
    names = [companion, *sources, *observers]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise keys.KeyMaterialError(f"names must be distinct: {', '.join(repeated)} given more than once")
    d = Path(directory).expanduser()
    if d.is_dir():
        _check_overwrite(d, names, mavlink_key, force)
    _make_directory(d)
    d = d.resolve()
    # the names sources may reach the companion by: loopback, the --connect hosts, specific --listen hosts
    companion_hosts = list(dict.fromkeys(["localhost", "127.0.0.1", *_hosts_of(connect), *_hosts_of(listen), *hosts]))
    try:
        ca = keys.create_ca(f"{companion}-ca")
        out = Deployment(
            d,
            keys.write_certificate(ca, d / "ca.pem"),
            keys.write_private_key(ca, d / "ca.key"),
            companion,
            sources,
            observers,
        )
        for name in names:
            ident = keys.issue_identity(ca, name, hosts=companion_hosts if name == companion else (), days=days)
            out.keys[name] = keys.write_private_key(ident, d / f"{name}.key")
            out.certs[name] = keys.write_certificate(ident, d / f"{name}.pem")
        common = {"ca_cert": out.ca_cert}
        cfg = access.companion_config(
            **common,
            key=out.keys[companion],
            cert=out.certs[companion],
            listen=listen,
            sysid=sysid,
            sources=sources,
            observers=observers,
        )
        out.configs[companion] = access.write_config(cfg, d / f"{companion}.json5")
        for name in [*sources, *observers]:
            cfg = access.peer_config(**common, key=out.keys[name], cert=out.certs[name], connect=connect)
            out.configs[name] = access.write_config(cfg, d / f"{name}.json5")
        if mavlink_key:
            out.mavlink_key = _write_mavlink_key(d / MAVLINK_KEY)
    except OSError as exc:
        raise keys.KeyMaterialError(
            f"{getattr(exc, 'filename', None) or d}: cannot write: {exc.strerror or exc}"
        ) from None
    log.info("deployment in %s: companion %s, sources %s, observers %s", d, companion, sources, observers)
    return out
