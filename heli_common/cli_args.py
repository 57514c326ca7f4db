"""Command-line parsing shared by ``companion`` and ``sim-vehicle``.

Two things that plain ``argparse`` gets wrong for this project's users:

- an option value that begins with a minus sign, such as a southern latitude
  (``--home -33.8688,151.2093,20,0``) or a NED vector (``--pos -5,3,-20``), is taken for an
  option and refused with "expected one argument". :class:`ArgumentParser` accepts it: before
  parsing it joins ``--option -3...`` into ``--option=-3...`` for every option of the parser
  that takes one value, when the value looks like a number (a minus sign, then a digit, or a
  point and a digit). ``--option=-3...`` is accepted as it is;
- options shared by a command's actions (``companion threat --zenoh-config F add ...``) are
  accepted only after the action. :func:`add_shared_options` adds them to the command and to
  every action, the action's copy with ``default=argparse.SUPPRESS`` so that a value given
  before the action is not reset by the action's default. Before the action, an option of
  several values (``nargs="+"``) takes one value per occurrence (repeat it), so that it does
  not swallow the action's name.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Iterable, Sequence

NEGATIVE_VALUE = re.compile(r"^-\.?\d")
"""A token that is a value, not an option: ``-33.8``, ``-1,1,0``, ``-.5,2,3``."""

ONE_VALUE_NARGS = (None, 1, "?")
"""``nargs`` of the options whose next token may be joined to them (one value)."""


def join_negative_values(argv: Sequence[str], value_options: Iterable[str]) -> list[str]:
    """Join ``OPTION VALUE`` into ``OPTION=VALUE`` where ``VALUE`` begins with a minus sign and a digit.

    Parameters
    ----------
    argv : sequence of str
        The command-line tokens (without the program name).
    value_options : iterable of str
        Option strings that take exactly one value (``--home``, ``-o``).

    Returns
    -------
    list of str
        The tokens, with every such pair joined; tokens after ``--`` are left alone.
    """
    options = set(value_options)
    out: list[str] = []
    tokens = list(argv)
    i = 0
    while i < len(tokens):
        token = tokens[i]
        if token == "--":
            return out + tokens[i:]
        following = tokens[i + 1] if i + 1 < len(tokens) else None
        if token in options and following is not None and NEGATIVE_VALUE.match(following):
            out.append(f"{token}={following}")
            i += 2
            continue
        out.append(token)
        i += 1
    return out


class ArgumentParser(argparse.ArgumentParser):
    """An ``argparse.ArgumentParser`` whose options take values beginning with a minus sign.

    Subparsers made by :meth:`add_subparsers` are of the same class (argparse's default), so a
    whole command tree gets the behaviour from its root.
    """

    def value_options(self) -> list[str]:
        """The option strings of this parser that take one value.

        Returns
        -------
        list of str
            e.g. ``["--home", "--origin", "--out", ...]``.
        """
        return [s for action in self._actions if action.nargs in ONE_VALUE_NARGS for s in action.option_strings]

    def parse_known_args(self, args=None, namespace=None):
        """``argparse.ArgumentParser.parse_known_args`` after :func:`join_negative_values`."""
        import sys

        argv = sys.argv[1:] if args is None else list(args)
        return super().parse_known_args(join_negative_values(argv, self.value_options()), namespace)


class SuppressedDefaults:
    """Adds arguments to ``parser`` with ``default=argparse.SUPPRESS`` (an action's copy of shared options).

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
        Where the arguments go.
    """

    def __init__(self, parser) -> None:
        self._parser = parser

    def add_argument(self, *args, **kwargs) -> argparse.Action:
        """``parser.add_argument`` with ``default=argparse.SUPPRESS``."""
        return self._parser.add_argument(*args, **{**kwargs, "default": argparse.SUPPRESS})

    def add_mutually_exclusive_group(self, **kwargs) -> SuppressedDefaults:
        """A mutually exclusive group of ``parser`` whose arguments have no defaults either."""
        return SuppressedDefaults(self._parser.add_mutually_exclusive_group(**kwargs))


class BeforeAction:
    """Adds arguments to a command's ``parser``; an option of several values takes one per occurrence.

    ``--zenoh-connect A B add`` would take ``add`` for an endpoint; before the action the
    option is ``--zenoh-connect A --zenoh-connect B add`` (``action="extend"``, ``nargs=1``).

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
        Where the arguments go.
    """

    def __init__(self, parser) -> None:
        self._parser = parser

    def add_argument(self, *args, **kwargs) -> argparse.Action:
        """``parser.add_argument``, an option of ``nargs`` ``"+"`` or ``"*"`` made repeatable instead."""
        if kwargs.get("nargs") in ("+", "*"):
            kwargs = {
                **kwargs,
                "nargs": 1,
                "action": "extend",
                "help": f"{kwargs.get('help', '')} (before the action: one per option, repeat it)",
            }
        return self._parser.add_argument(*args, **kwargs)

    def add_mutually_exclusive_group(self, **kwargs) -> BeforeAction:
        """A mutually exclusive group of ``parser``, its options made the same way."""
        return BeforeAction(self._parser.add_mutually_exclusive_group(**kwargs))


def add_shared_options(
    command: argparse.ArgumentParser, actions: Iterable[argparse.ArgumentParser], add: Callable[[object], None]
) -> None:
    """Accept the options ``add`` defines both before and after a command's action.

    Parameters
    ----------
    command : argparse.ArgumentParser
        The command's parser (``companion threat``): gets the options with their defaults.
    actions : iterable of argparse.ArgumentParser
        The parsers of its actions (``add``, ``move``, ...): get the same options without
        defaults, so that a value given before the action stays (and one given after it wins).
    add : callable
        ``add(parser)`` calls ``parser.add_argument`` (and may call
        ``parser.add_mutually_exclusive_group``) for each shared option. A shared option must
        not be ``required`` (given before the action, the action's parser would miss it).
    """
    add(BeforeAction(command))
    for action in actions:
        add(SuppressedDefaults(action))
