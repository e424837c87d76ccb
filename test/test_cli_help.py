"""Every ``dualarm`` verb's ``--help`` as printed (issue 38, item 6).

argparse %-formats an argument's ``help`` (``%(default)s``; a literal percent is ``%%`` there) and a
sub-command's ``help``, but prints a parser's ``description`` as written (unless it holds ``%(prog)``):
a ``%%`` in a description is printed as ``%%``. Each parser's help is formatted here, as ``--help``
would print it, and must hold no ``%%``.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator

from dualarm_control.app.cli import ROBOT_HELP, build_parser


def all_parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> Iterator[
        tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """``parser`` and every sub-command's parser under it, with the verbs leading to it."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from all_parsers(sub, (*path, name))


def test_every_help_is_printed_without_a_doubled_percent() -> None:
    parsers = dict(all_parsers(build_parser()))
    assert ("sweep",) in parsers and ("hardware", "check") in parsers and ("topic", "echo") in parsers
    doubled = [" ".join(("dualarm", *path, "--help")) for path, parser in parsers.items()
               if "%%" in parser.format_help()]
    assert not doubled, f"a literal '%%' in {doubled}"
    assert "95 % CIs" in parsers[("sweep",)].format_help().replace("\n", " ").replace("  ", " ")


def test_hardware_check_robot_help_is_its_own() -> None:
    """``--robot`` of ``hardware check`` names what it checks and its default, not launch's text."""
    check = dict(all_parsers(build_parser()))[("hardware", "check")]
    robot = next(a for a in check._actions if "--robot" in a.option_strings)
    assert robot.help != ROBOT_HELP
    assert robot.help is not None and "profile" in robot.help and "robot parameter" in robot.help
