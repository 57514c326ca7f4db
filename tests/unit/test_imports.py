"""Every module of the packages imports (a module only a subprocess starts, e.g. ``companion
serve``'s, would otherwise fail only in an integration test)."""

import importlib
import pkgutil

import pytest

import companion
import heli_common
import heli_model
import mavlink_signing
import sim_vehicle

MODULES = sorted(
    m.name
    for pkg in (companion, sim_vehicle, heli_model, heli_common, mavlink_signing)
    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + ".")
)


def test_the_packages_have_their_modules():
    assert len(MODULES) > 200 and "companion.flight.executor" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_the_module_imports(name):
    importlib.import_module(name)
