"""Docs that cannot go stale: every command the README and docs/ show is one the tools accept.

Each shell block (```sh / ```bash / an unlabelled block whose lines are commands) of README.md
and docs/*.md is read line by line (continuations joined, comments, ``&`` and prompts dropped).
A ``companion`` or ``sim-vehicle`` command must parse with the command's own argparse parser;
a ``make`` target must be in the Makefile; a script run with the venv's Python must exist. The
flights these commands start are flown by the integration tests (the demo, SITL, ArduPilot,
campaign and fleet tests); this test makes sure that what the docs say is what those parsers
take, option by option.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest
from docs_blocks import DOCS, ROOT, blocks

from companion.cli import build_parser as companion_parser
from sim_vehicle.cli import build_parser as sim_vehicle_parser

SHELL_LANGS = {"sh", "bash", "shell", "console", ""}
TOOLS = ("companion", "sim-vehicle")


def _commands(lines: list[str], start: int):
    """(line number, argv) of each command of a shell block."""
    pending, first = "", start
    for number, raw in enumerate(lines, start):
        line = re.sub(r"^\s*\$ ", "", raw)
        if not pending:
            first = number
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        text = re.sub(r"<[^<>]+>", "X", (pending + line).strip())  # <placeholder>
        pending = ""
        try:
            words = shlex.split(text, comments=True)
        except ValueError:
            continue
        for part in _split_on_operators(words):
            yield first, part


def _split_on_operators(words: list[str]):
    """Commands of a line joined by ``&``, ``&&``, ``;``, ``|`` (a trailing ``&`` dropped)."""
    part = []
    for word in words:
        if word in ("&", "&&", ";", "|", "||"):
            if part:
                yield part
            part = []
        else:
            part.append(word.rstrip(";&") if word.endswith(("&", ";")) and len(word) > 1 else word)
    if part:
        yield part


def _tool(argv: list[str]) -> tuple[str, list[str]] | None:
    """The project command and its arguments, past env assignments, ``nice`` and ``.venv/bin/``."""
    words = list(argv)
    while words and (re.match(r"^[A-Z_][A-Z0-9_]*=", words[0]) or words[0] in ("sudo", "exec", "time", "nohup")):
        words.pop(0)
    if words and words[0] == "nice":
        words.pop(0)
        if words and words[0] == "-n":
            words[:2] = []
    if not words:
        return None
    if words[0].endswith("/"):
        return None  # a folder of a layout tree
    name = Path(words[0]).name
    return (name, words[1:]) if name in TOOLS or name in ("make", "python", "python3") else None


def _synopsis(argv: list[str]) -> bool:
    """A usage line (``[--opt X]``, ``a|b``, ``...``), not a command."""
    return any(w.startswith(("[", "(")) or w.endswith("]") or "..." in w or re.search(r"\w\|\w", w) for w in argv)


def _documented():
    out = []
    for path in DOCS:
        for lang, start, lines in blocks(path.read_text()):
            if lang not in SHELL_LANGS or (lang == "" and any(re.search(r"[\u2500-\u25ff]", ln) for ln in lines)):
                continue  # not shell, or a diagram
            for number, argv in _commands(lines, start):
                found = _tool(argv)
                if found is not None and not _synopsis(found[1]):
                    out.append(pytest.param(*found, id=f"{path.relative_to(ROOT)}:{number}"))
    return out


DOCUMENTED = _documented()
PARSERS = {"companion": companion_parser, "sim-vehicle": sim_vehicle_parser}


def test_the_docs_show_commands_of_every_tool():
    names = {p.values[0] for p in DOCUMENTED}
    assert {"companion", "sim-vehicle", "make"} <= names
    assert len(DOCUMENTED) >= 40


@pytest.mark.parametrize("name, args", DOCUMENTED)
def test_a_documented_command_is_accepted(name, args):
    if name == "make":
        targets = set(re.findall(r"^([\w.-]+):", (ROOT / "Makefile").read_text(), re.M))
        assert set(a for a in args if not a.startswith("-") and "=" not in a) <= targets
        return
    if name.startswith("python"):
        script = next((a for a in args if not a.startswith("-")), None)
        if script is not None and script.endswith(".py"):
            assert (ROOT / script).exists(), script
        return
    if any(a in ("-h", "--help") for a in args):
        return
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            PARSERS[name]().parse_args(args)
        except SystemExit as exc:
            pytest.fail(f"{name} {' '.join(args)}: refused by its parser (exit {exc.code}): {err.getvalue().strip()}")


def test_a_wrong_option_is_caught_by_this_test():
    """The check itself can fail: a misspelt option is refused by the parser it uses."""
    with contextlib.redirect_stderr(io.StringIO()), pytest.raises(SystemExit):
        companion_parser().parse_args(["run", "--misson", "x.plan"])
    assert isinstance(companion_parser(), argparse.ArgumentParser)
