"""``companion keys init``: CA, identities, zenoh configurations (companion.security, threats.access)."""

from __future__ import annotations

import ipaddress
import json
import stat

import pytest

from companion.cli import main
from companion.security import keys
from companion.security.deployment import init_deployment


@pytest.fixture(scope="module")
def deployment(tmp_path_factory):
    d = tmp_path_factory.mktemp("deploy")
    return init_deployment(
        d,
        sysid=3,
        sources=["radar1", "radar2"],
        observers=["gcs"],
        listen=["tls/0.0.0.0:7447"],
        connect=["tls/10.1.2.3:7447"],
        hosts=["heli.local"],
    )


def _load_json5(path):
    text = path.read_text()
    assert text.startswith("//")
    return json.loads(text.split("\n", 1)[1])


def test_every_identity_has_a_private_key_readable_by_the_owner_only(deployment):
    for path in [deployment.ca_key, *deployment.keys.values()]:
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
        assert path.read_text().startswith("-----BEGIN PRIVATE KEY-----")
    assert set(deployment.keys) == {"companion", "radar1", "radar2", "gcs"}


def test_certificates_verify_against_the_ca_and_carry_their_names(deployment):
    ca = keys.load_certificate(deployment.ca_cert)
    for name, path in deployment.certs.items():
        cert = keys.load_certificate(path)
        keys.verify_signed_by(cert, ca)
        assert keys.common_name(cert) == name


def test_a_certificate_of_another_ca_does_not_verify(deployment):
    stranger = keys.issue_identity(keys.create_ca("other-ca"), "radar1")
    with pytest.raises(keys.KeyMaterialError, match="not by the CA"):
        keys.verify_signed_by(stranger.cert, keys.load_certificate(deployment.ca_cert))
    ca = keys.create_ca("companion-ca")  # same name, other key: the signature fails
    forged = keys.issue_identity(ca, "radar1")
    with pytest.raises(keys.KeyMaterialError, match="signature"):
        keys.verify_signed_by(forged.cert, keys.load_certificate(deployment.ca_cert))


def test_the_companion_certificate_names_the_hosts_sources_connect_to(deployment):
    from cryptography import x509

    cert = keys.load_certificate(deployment.certs["companion"])
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert {"companion", "localhost", "heli.local"} <= set(san.get_values_for_type(x509.DNSName))
    assert {ipaddress.ip_address("127.0.0.1"), ipaddress.ip_address("10.1.2.3")} <= set(
        san.get_values_for_type(x509.IPAddress)
    )
    assert "0.0.0.0" not in str(san)


def test_configs_load_in_zenoh_and_name_the_files_written(deployment):
    import zenoh

    for name, path in deployment.configs.items():
        zenoh.Config.from_file(str(path))
        cfg = _load_json5(path)
        tls = cfg["transport"]["link"]["tls"]
        assert tls["enable_mtls"] is True and tls["root_ca_certificate"] == str(deployment.ca_cert)
        assert tls["connect_certificate"] == str(deployment.certs[name])
        assert tls["connect_private_key"] == str(deployment.keys[name])
        assert cfg["scouting"]["multicast"]["enabled"] is False
    comp = _load_json5(deployment.configs["companion"])
    assert comp["listen"]["endpoints"] == ["tls/0.0.0.0:7447"]
    assert comp["transport"]["link"]["tls"]["listen_certificate"] == str(deployment.certs["companion"])
    src = _load_json5(deployment.configs["radar1"])
    assert src["connect"]["endpoints"] == ["tls/10.1.2.3:7447"] and src["listen"]["endpoints"] == []
    assert "access_control" not in src and "listen_private_key" not in src["transport"]["link"]["tls"]


def test_the_acl_binds_each_source_to_its_own_key_space(deployment):
    acl = _load_json5(deployment.configs["companion"])["access_control"]
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert all(r["permission"] == "allow" for r in rules.values())
    for policy in acl["policies"]:
        assert set(policy["rules"]) <= set(rules) and set(policy["subjects"]) <= set(subjects)
    # who may put/delete where: only <name> on uav/3/threats/<name>/*
    puts = {}
    for policy in acl["policies"]:
        for rid in policy["rules"]:
            if "put" in rules[rid]["messages"] and "ingress" in rules[rid]["flows"]:
                for sid in policy["subjects"]:
                    for cn in subjects[sid]["cert_common_names"]:
                        puts.setdefault(cn, []).extend(rules[rid]["key_exprs"])
    assert puts == {"radar1": ["uav/3/threats/radar1/*"], "radar2": ["uav/3/threats/radar2/*"]}
    assert set(subjects["readers"]["cert_common_names"]) == {"radar1", "radar2", "gcs"}
    assert "gcs" not in subjects["sources"]["cert_common_names"]
    assert rules["telemetry-out"]["key_exprs"] == ["uav/3/status", "uav/3/events", "uav/3/path"]
    assert rules["telemetry-out"]["flows"] == ["egress"]


def test_a_directory_with_other_files_is_taken(tmp_path):
    (tmp_path / "companion.toml").write_text("seed = 0\n")
    (tmp_path / "companion.service").write_text("[Unit]\n")
    dep = init_deployment(tmp_path)
    assert dep.sources == ["source1"] and (tmp_path / "source1.json5").is_file()
    assert (tmp_path / "companion.toml").read_text() == "seed = 0\n"


def test_existing_key_files_are_named_and_kept_unless_forced(tmp_path):
    init_deployment(tmp_path, sources=["radar1"])
    first = (tmp_path / "ca.pem").read_text()
    with pytest.raises(
        keys.KeyMaterialError, match="ca.key, ca.pem, companion.key.*radar1.json5, mavlink.key exist already.*--force"
    ):
        init_deployment(tmp_path, sources=["radar1"])
    assert (tmp_path / "ca.pem").read_text() == first
    init_deployment(tmp_path, sources=["radar1"], force=True)
    assert (tmp_path / "ca.pem").read_text() != first  # a new CA


def test_the_mavlink_key_is_a_passphrase_for_mavproxy_readable_by_the_owner_only(tmp_path, deployment):
    import hashlib

    from mavlink_signing import load_key

    text = deployment.mavlink_key.read_text().strip()
    assert stat.S_IMODE(deployment.mavlink_key.stat().st_mode) == 0o600
    assert len(text) >= 43 and load_key(deployment.mavlink_key) == hashlib.sha256(text.encode()).digest()
    dep = init_deployment(tmp_path, mavlink_key=False)
    assert dep.mavlink_key is None and not (tmp_path / "mavlink.key").exists()


def test_an_existing_mavlink_key_is_kept_with_no_mavlink_key(tmp_path, capsys):
    (tmp_path / "mavlink.key").write_text("the flight controller's passphrase\n")
    assert main(["keys", "init", str(tmp_path)]) == 2
    assert "mavlink.key exist already" in capsys.readouterr().err
    assert main(["keys", "--no-mavlink-key", "init", str(tmp_path)]) == 0
    assert (tmp_path / "mavlink.key").read_text() == "the flight controller's passphrase\n"


def test_one_existing_file_of_the_deployment_is_enough_to_refuse(tmp_path):
    (tmp_path / "radar2.key").write_text("x")
    with pytest.raises(keys.KeyMaterialError, match=r": radar2.key exist already"):
        init_deployment(tmp_path, sources=["radar2"])
    assert not (tmp_path / "ca.key").exists()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"sources": ["radar 1"]}, "--source"),
        ({"sources": ["local"]}, "reserved"),
        ({"sources": []}, "at least one"),
        ({"sources": ["a"], "observers": ["a"]}, "distinct"),
        ({"companion": "radar1", "sources": ["radar1"]}, "distinct"),
        ({"sysid": 0}, "--sysid"),
        ({"listen": ["tcp/0.0.0.0:7447"]}, "listen\\[0\\]: expected a tls/"),
    ],
)
def test_bad_arguments_name_what_is_wrong(tmp_path, kwargs, message):
    with pytest.raises(Exception, match=message):
        init_deployment(tmp_path / "d", **kwargs)


def test_keys_init_command_writes_and_refuses_an_existing_deployment(tmp_path, capsys):
    d = tmp_path / "deploy"
    assert main(["keys", "init", str(d), "--source", "radar1", "--observer", "gcs"]) == 0
    out = capsys.readouterr().out
    assert "source    radar1" in out and "observer  gcs" in out and "--zenoh-config" in out
    assert main(["keys", "init", str(d)]) == 2
    err = capsys.readouterr().err
    assert "ca.key" in err and "exist already" in err and "--force" in err


def test_keys_init_writes_to_the_user_config_directory_by_default(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    assert main(["keys", "init", "--source", "radar1"]) == 0
    d = tmp_path / "cfg" / "heli-companion" / "keys"
    assert (d / "radar1.key").is_file() and str(d / "radar1.json5") in capsys.readouterr().out
    assert stat.S_IMODE(d.stat().st_mode) == 0o700


@pytest.mark.parametrize(
    "env, expected",
    [
        ({"XDG_CONFIG_HOME": "/x/cfg", "HOME": "/home/u"}, "/x/cfg/heli-companion/keys"),
        ({"XDG_CONFIG_HOME": "", "HOME": "/home/u"}, "/home/u/.config/heli-companion/keys"),
        ({"XDG_CONFIG_HOME": "rel/cfg", "HOME": "/home/u"}, "/home/u/.config/heli-companion/keys"),
        ({"HOME": "/home/u"}, "/home/u/.config/heli-companion/keys"),
    ],
)
def test_the_default_keys_directory_follows_xdg(env, expected):
    from companion.security.paths import default_keys_dir

    assert str(default_keys_dir(env)) == expected


@pytest.mark.parametrize(
    "path",
    [
        "deploy/ca.key",
        "deploy/radar1.key",
        "deploy/radar1.pem",
        "deploy/gcs.json5",
        "deploy/mavlink.key",
        "keys/companion.key",
        "heli.key",
    ],
)
def test_key_files_in_the_tree_are_ignored_by_git(path):
    import shutil
    import subprocess
    from pathlib import Path

    repo = Path(__file__).resolve().parents[3]
    if shutil.which("git") is None or not (repo / ".git").exists():
        pytest.skip("not a git checkout")
    done = subprocess.run(["git", "-C", str(repo), "check-ignore", "-q", "--no-index", path])
    assert done.returncode == 0, f"{path} is not ignored by .gitignore"


def test_a_file_path_is_refused(tmp_path):
    f = tmp_path / "file"
    f.write_text("")
    with pytest.raises(keys.KeyMaterialError, match="not a directory"):
        init_deployment(f)
