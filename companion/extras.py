"""The optional features and the extras that install them (issue 25, item 5).

``pip install heli-companion`` installs what a flight needs (the planners, the model, MAVLink,
MAVSDK, zenoh). The rest comes with an extra (``pyproject.toml``):

- ``view``: the live Foxglove view and MCAP records (foxglove-sdk, mcap): ``--foxglove``,
  ``--record FILE.mcap``, reading an MCAP record;
- ``report``: plots and the terminal progress (matplotlib, rich): ``companion report``,
  ``companion plan --plot``, ``companion demo``;
- ``keys``: certificates for zenoh's mutual TLS (cryptography): ``companion keys``, a
  ``--zenoh-config`` that names certificates;
- ``campaign``: the validation campaign (pyarrow, distributed, rich, matplotlib);
- ``test``, ``bench``: the test and benchmark tools (with the extras above); ``all``.

Every import of an optional package goes through :func:`require`, inside the function that
needs it. A missing one raises :class:`MissingExtra`, which ``companion`` prints as one line,
``companion report: needs the 'report' extra: pip install 'heli-companion[report]'``, and
exits with status 2.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from companion.errors import CompanionError

__all__ = ["DISTRIBUTION", "EXTRA_PACKAGES", "MissingExtra", "require"]

#: The project's name on PyPI (``[project] name`` in ``pyproject.toml``).
DISTRIBUTION = "heli-companion"
#: Optional top-level module -> the distribution that provides it (each listed in the extras
#: that :func:`require` names for it; ``tests/unit/test_extras.py`` checks pyproject).
EXTRA_PACKAGES = {
    "foxglove": "foxglove-sdk",
    "mcap": "mcap",
    "matplotlib": "matplotlib",
    "rich": "rich",
    "cryptography": "cryptography",
    "pyarrow": "pyarrow",
    "distributed": "distributed",
}


class MissingExtra(CompanionError):
    """An optional package is not installed: names the extra that installs it.

    Parameters
    ----------
    extra : str
        The extra (``report``, ``view``, ...).
    module : str
        The module that could not be imported.
    """

    def __init__(self, extra: str, module: str) -> None:
        super().__init__(f"needs the '{extra}' extra: pip install '{DISTRIBUTION}[{extra}]'")
        self.extra = extra
        self.module = module


def require(extra: str, module: str) -> ModuleType:
    """Import ``module`` (an optional package, or one of its submodules) and return it.

    Parameters
    ----------
    extra : str
        The extra that installs it, named in the error.
    module : str
        Dotted module name, e.g. ``"matplotlib.pyplot"``.

    Returns
    -------
    module

    Raises
    ------
    MissingExtra
        When the package (or a package it needs) is not installed.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError:
        raise MissingExtra(extra, module) from None
