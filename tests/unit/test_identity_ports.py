"""Identity and ports that scale to several vehicles on one machine (issue 15, part 1):
``sim-vehicle --instance N`` and ``companion run --instance N`` meet on 14540 + N, the zenoh
prefix is ``uav/<N+1>``, and a companion's default zenoh endpoint (7447 + sysid) never takes a
zenoh router's 7447 nor another system's companion's."""

import pytest

from companion.cli import build_parser as companion_parser
from companion.commands.run import flight_settings
from companion.errors import ConfigError
from companion.threats.settings import ZENOH_ROUTER_PORT, ZenohSettings, default_listen
from companion.threats.transport.bus import ThreatBus
from sim_vehicle.cli import _settings_from_args
from sim_vehicle.cli import build_parser as sim_parser


def companion_settings(*argv):
    return flight_settings(companion_parser().parse_args(["run", *argv]))


def sim_outs(*argv):
    return _settings_from_args(sim_parser().parse_args(list(argv))).link.out


@pytest.mark.parametrize("sysid", [1, 2, 7, 255])
def test_default_zenoh_endpoints_of_systems_never_collide_with_a_router_or_each_other(sysid):
    settings = ZenohSettings(sysid=sysid)
    assert settings.listen is None
    assert settings.listen_endpoints == default_listen(sysid) == (f"tcp/127.0.0.1:{7447 + sysid}",)
    assert not settings.listen_endpoints[0].endswith(f":{ZENOH_ROUTER_PORT}")
    assert ThreatBus.from_settings(settings).listen == settings.listen_endpoints
    others = {default_listen(other)[0] for other in range(1, 256) if other != sysid}
    assert settings.listen_endpoints[0] not in others


def test_explicit_zenoh_endpoints_are_kept_and_an_empty_session_is_refused():
    assert ZenohSettings(listen=("tcp/0.0.0.0:9000",)).listen_endpoints == ("tcp/0.0.0.0:9000",)
    assert ZenohSettings(listen=(), connect=("tcp/10.0.0.1:7447",)).listen_endpoints == ()
    with pytest.raises(ConfigError, match="zenoh.listen"):
        ZenohSettings(listen=())


def test_companion_instance_matches_the_sim_vehicle_instance():
    for n in (0, 1, 4):
        s = companion_settings("--instance", str(n))
        port = int(s.link.connect.rsplit(":", 1)[1])
        assert sim_outs("--instance", str(n))[1] == f"127.0.0.1:{port}" and port == 14540 + n
        assert s.zenoh.sysid == n + 1 == 1 + n  # sim-vehicle's sysid is 1 + N
        assert s.zenoh.listen_endpoints == (f"tcp/127.0.0.1:{7448 + n}",)


def test_explicit_options_win_over_the_instance_shortcut():
    s = companion_settings(
        "--instance", "2", "--connect", "udpin://0.0.0.0:15000", "--zenoh-listen", "tcp/0.0.0.0:9100"
    )
    assert s.link.connect == "udpin://0.0.0.0:15000" and s.zenoh.listen_endpoints == ("tcp/0.0.0.0:9100",)
    assert s.zenoh.sysid == 3
    assert sim_outs("--instance", "2", "--out", "127.0.0.1:16000") == ("127.0.0.1:16000",)
    assert sim_outs() == ("127.0.0.1:14550", "127.0.0.1:14540")


def test_an_instance_out_of_range_is_named():
    with pytest.raises(ConfigError, match="--instance: expected 0..200, got 201"):
        companion_settings("--instance", "201")


def test_the_prefix_follows_the_vehicles_system_id_unless_set():
    from companion.threats.settings import ZenohSettings

    unset = ZenohSettings()
    assert unset.sysid is None and unset.prefix_sysid == 1
    got = unset.for_vehicle(3)
    assert got.sysid == 3 and got.listen_endpoints == ("tcp/127.0.0.1:7450",)
    assert ZenohSettings(sysid=2).for_vehicle(3).sysid == 2  # set: kept
