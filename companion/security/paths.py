"""Where ``companion keys init`` writes by default: the user's configuration directory.

Light on purpose (``companion --help`` shows the default without loading the key code).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["KEYS_SUBDIR", "default_keys_dir"]

KEYS_SUBDIR = Path("heli-companion") / "keys"
"""Under the XDG configuration directory: where ``companion keys init`` writes by default."""


def default_keys_dir(environ=None) -> Path:
    """``$XDG_CONFIG_HOME/heli-companion/keys``, else ``~/.config/heli-companion/keys``.

    Parameters
    ----------
    environ : mapping, optional
        The environment (default ``os.environ``). A relative ``XDG_CONFIG_HOME`` is ignored, as
        the XDG Base Directory specification says.

    Returns
    -------
    Path
        The directory (not created here).
    """
    env = os.environ if environ is None else environ
    base = env.get("XDG_CONFIG_HOME", "")
    if not base or not Path(base).is_absolute():
        home = env.get("HOME") or str(Path.home())
        base = str(Path(home) / ".config")
    return Path(base) / KEYS_SUBDIR
