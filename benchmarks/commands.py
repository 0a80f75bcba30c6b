"""README's command table, generated from the ``peghole`` parser itself.

One row per command (a leaf of the sub-command tree that :func:`peghole_mjx.cli.main.build_parser`
builds): its usage, shortened to the arguments a call needs (the required options, then the
positionals), and the help line its group module gave it. ``--help`` lists the optional
arguments, left out of the table to keep README.md within its size (tests/test_docs.py).
``python -m benchmarks.tables`` writes it between the ``<!-- table:commands -->`` markers of
README.md; tests/test_commands_table.py checks that the committed table is the parser's.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from benchmarks.common import table
from peghole_mjx.cli.main import build_parser

#: a list of choices longer than this (characters) shows as the argument's name
MAX_CHOICES = 24


def _braced(choices) -> str:
    return "{" + ",".join(str(c) for c in choices) + "}"


def _metavar(action: argparse.Action) -> str:
    """The argument's metavar as argparse prints it in a usage line."""
    if action.metavar is not None:
        name = action.metavar if isinstance(action.metavar, str) else " ".join(action.metavar)
    elif action.choices is not None and len(braced := _braced(action.choices)) <= MAX_CHOICES:
        name = braced
    else:
        name = action.dest if not action.option_strings else action.dest.upper()
    if action.nargs == "?":
        return f"[{name}]"
    if action.nargs == "*":
        return f"[{name} ...]"
    if action.nargs == "+":
        return f"{name} [{name} ...]"
    if isinstance(action.nargs, int):
        return " ".join([name] * action.nargs)
    return name


def _subparsers(action: argparse.Action) -> dict[str, argparse.ArgumentParser] | None:
    """The sub-command parsers by name if ``action`` is a parser's sub-command action."""
    choices = action.choices
    if isinstance(choices, dict) and all(
        isinstance(p, argparse.ArgumentParser) for p in choices.values()
    ):
        return choices
    return None


def usage(path: list[str], parser: argparse.ArgumentParser) -> str:
    """``peghole PATH`` with its required options, then its positionals, as
    ``peghole PATH --help`` orders them."""
    required, positional = [], []
    for action in parser._actions:  # argparse has no public list of a parser's arguments
        if "--help" in action.option_strings or _subparsers(action) is not None:
            continue
        if not action.option_strings:
            positional.append(_metavar(action))
        elif action.required:
            flag = action.option_strings[0]
            required.append(flag if action.nargs == 0 else f"{flag} {_metavar(action)}")
    return " ".join(["peghole", *path, *required, *positional])


def commands(
    parser: argparse.ArgumentParser, path: list[str] | None = None
) -> Iterator[tuple[str, str]]:
    """(usage, help line) of every command under ``parser``, in the parser's order."""
    path = path or []
    for action in parser._actions:
        subs = _subparsers(action)
        if subs is None:
            continue
        helps = {a.dest: a.help or "" for a in action._choices_actions}
        for name, sub in subs.items():
            if any(_subparsers(a) is not None for a in sub._actions):
                yield from commands(sub, [*path, name])
            else:
                yield usage([*path, name], sub), helps.get(name, "")


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|")


@table("commands")
def commands_table() -> str:
    """The Markdown table: one row per ``peghole`` command."""
    rows = ["| command | help |", "|---|---|"]
    rows += [f"| `{_cell(u)}` | {_cell(h)} |" for u, h in commands(build_parser())]
    return "\n".join(rows)


if __name__ == "__main__":
    print(commands_table())
