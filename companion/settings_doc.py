"""The settings reference, generated from the settings dataclasses (``docs/SETTINGS.md``).

Each key's type and default come from the dataclass field, its meaning from the numpydoc
``Parameters`` / ``Attributes`` section of the class that owns it, its unit from the name's
suffix (``_m``, ``_s``, ``_m_s`` ...). ``tools/settings_doc.py`` writes the file; a unit test
regenerates it and fails when the file drifts from the code.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import typing
from collections.abc import Iterator
from dataclasses import dataclass

__all__ = ["SettingDoc", "setting_docs", "field_descriptions", "unit_of", "settings_markdown", "reference_markdown"]

#: Name suffix -> unit, longest first.
UNITS: tuple[tuple[str, str], ...] = (
    ("_m_s2", "m/s²"),
    ("_m_s3", "m/s³"),
    ("_rad_s2", "rad/s²"),
    ("_rad_s", "rad/s"),
    ("_m_s", "m/s"),
    ("_1_m", "1/m"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_hz", "Hz"),
    ("_ms", "ms"),
    ("_us", "µs"),
    ("_m", "m"),
    ("_s", "s"),
    ("_pct", "%"),
)
_ENTRY = re.compile(r"^(\w+(?:\s*,\s*\w+)*)\s*:\s*(.*)$")
_SECTIONS = ("Parameters", "Attributes")


@dataclass(frozen=True)
class SettingDoc:
    """One settings key: dotted name, type, default (TOML-like text), unit and meaning."""

    key: str
    type: str
    default: str
    unit: str
    meaning: str


def unit_of(name: str) -> str:
    """The unit a key's name carries (``speed_m_s`` -> ``m/s``); empty when it carries none."""
    for suffix, unit in UNITS:
        if name.endswith(suffix) or (suffix == "_s" and "_s_" in name and name.endswith("_s")):
            return unit
    return ""


def field_descriptions(cls: type) -> dict[str, str]:
    """Field name -> description from the numpydoc Parameters/Attributes section of ``cls``.

    Grouped entries (``a, b : float``, possibly wrapped over lines) give each name the text.
    """
    lines = inspect.cleandoc(cls.__doc__ or "").splitlines()
    out: dict[str, str] = {}
    current: list[str] = []
    pending = ""  # a wrapped ``a, b,`` entry name line
    in_section = False
    for i, line in enumerate(lines):
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() in _SECTIONS and set(nxt.strip()) == {"-"}:
            in_section, current = True, []
            continue
        if not in_section or set(line.strip()) == {"-"}:
            continue
        if line.startswith(" "):
            for name in current:
                out[name] = f"{out[name]} {line.strip()}".strip()
        elif line.rstrip().endswith(","):
            pending += line.strip() + " "
        elif entry := _ENTRY.match(pending + line.strip()):
            current = [n.strip() for n in entry.group(1).split(",")]
            out.update({name: "" for name in current})
            pending = ""
        elif line.strip():
            in_section, current = False, []  # the next section (Raises, Notes ...)
    return out


def _type_text(tp: object) -> str:
    text = tp.__name__ if isinstance(tp, type) else str(tp)
    return text.replace("typing.", "").replace("NoneType", "None")


def _default_text(value: object) -> str:
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, tuple):
        return "[" + ", ".join(_default_text(v) for v in value) + "]"
    return repr(value)


def setting_docs(cls: type, instance: object | None = None, prefix: str = "") -> Iterator[SettingDoc]:
    """Every leaf key of the settings dataclass ``cls`` (depth first, in declaration order)."""
    instance = cls() if instance is None else instance
    hints = typing.get_type_hints(cls)
    meanings = field_descriptions(cls)
    for f in dataclasses.fields(cls):
        value = getattr(instance, f.name)
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            yield from setting_docs(type(value), value, key + ".")
            continue
        yield SettingDoc(
            key, _type_text(hints[f.name]), _default_text(value), unit_of(f.name), meanings.get(f.name, "")
        )


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def settings_markdown(cls: type, title: str) -> str:
    """One tree's reference as Markdown: a ``##`` title, one table per top-level table."""
    out = [f"## {title}"]
    section = None
    for doc in setting_docs(cls):
        top = doc.key.split(".")[0] if "." in doc.key else ""
        if top != section:
            section = top
            out += [
                "",
                f"### `[{top}]`" if top else "### Top level",
                "",
                "| key | type | default | unit | meaning |",
                "|---|---|---|---|---|",
            ]
        out.append(f"| `{doc.key}` | {_cell(doc.type)} | `{_cell(doc.default)}` | {doc.unit} | {_cell(doc.meaning)} |")
    return "\n".join(out) + "\n"


INTRO = """\
<!-- Generated by tools/settings_doc.py from the settings dataclasses: do not edit.
     tests/unit/test_settings_doc.py fails when this file drifts from the code. -->

# Settings reference

Every key of the two settings trees: its type, default, unit and meaning. A TOML file overrides
only what it names (`companion run --config FILE`, `sim-vehicle --config FILE`);
`companion run --print-config` prints the effective tree as TOML (`--print-config json`: as
JSON). Units follow the key's suffix (`_m`, `_s`, `_m_s`, `_hz` ...). Times are the vehicle's
(simulated) time unless the meaning says wall clock.
"""


def reference_markdown(trees) -> str:
    """The whole ``docs/SETTINGS.md``: the introduction, then each settings tree.

    Parameters
    ----------
    trees : sequence of (dataclass type, str)
        Each tree's root class and its section title (``tools/settings_doc.py`` gives the
        companion's and ``sim-vehicle``'s).
    """
    return "\n".join((INTRO, *(settings_markdown(tree, title) for tree, title in trees)))
