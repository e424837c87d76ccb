"""README.md and docs/*.md against the code: every ``dualarm`` command line parses, every repository
path exists (issue 38, item 6). Nothing runs: the command lines go through the real parser
(``dualarm_control.app.cli.build_parser``) only.

**Command lines.** In a fenced block, each shell command (``\\`` continuations joined, ``#`` comments
dropped, split at ``;``, ``&&``, ``||``, ``|``) whose first word is ``dualarm`` (after a ``$`` prompt
and ``VAR=value`` assignments; also ``.venv/bin/dualarm``) must parse. Such a line that the shell
cannot split (an open quote) fails too. Not command lines: output (``dualarm param: error: ...``, whose
second word ends with ``:``) and synopses (a ``[--option VALUE]`` group), which are checked as
references. An inline code span (it may wrap across lines) that begins with ``dualarm`` is a command
line when it parses; otherwise it is a *reference* to a verb or an option (``dualarm launch --record``,
``dualarm view BAG --video``), accepted only when the parse failed for a missing argument or value or
on a placeholder (``HZ``, ``SPEC``, ``...``, ``<name>``: capitals or brackets). Every command line and
reference must name existing verbs, and only options of the verb it names.

**Paths.** Every word of README.md and docs/*.md that begins with ``config/``, ``urdf/``, ``launch/``,
``test/``, ``dualarm_control/``, ``dualarm_sim/`` or ``docs/`` names a file or directory of this
repository and must exist: data the commands read (``config/solvers/sparse_qp.yaml``,
``test/data/short.yaml``), and the sources and tests the prose points to
(``dualarm_control/ros/env.py``, ``test/test_bag.py::test_name``). A word is such a path only at a word
start: not after ``/``, ``.``, ``~``, ``$``, ``-`` or a letter (``install/.../share/dualarm_control/config/x``
is an install path, not checked). Output paths (``out/...``, ``/tmp/...``, ``BAG``, ``DIR``) and user
files (``my_robot.yaml``, ``my_cell.yaml``) have none of these prefixes and are never required. In a
path, the first placeholder component (``<name>``, ``{a,b}``, ``$VAR``, ``...``, ``NAME`` in capitals)
ends the checked part (``config/robots/<name>.yaml``: ``config/robots`` must exist); ``*`` is a glob
that must match; ``::test`` and a trailing ``.`` are dropped. :data:`NOT_PATHS` lists the words with
such a prefix that are not paths. Files named ``*.launch.py`` must be in launch/.

**Lists that follow the tree.** README's Layout block names existing directories, and every package
directory (``dualarm_control/**``, ``dualarm_sim``), every ``config/`` directory and ``test/data``; the
README's set-up installs the Makefile's extras; the apt route's ``pip install`` (docs/ros2.md) installs
each of setup.py's ``install_requires`` that it does not leave to apt.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import glob
import io
import re
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from dualarm_control.app.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
DOCS = (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")))
REPO_PREFIXES = ("config", "urdf", "launch", "test", "dualarm_control", "dualarm_sim", "docs")
NOT_PATHS = {
    "dualarm_control/plan/1": "the format tag of plan.json (docs/planner.md)",
    "config/urdf/launch": "three directories of the share directory (docs/ros2.md)",
    "test/test_x.py": "a placeholder of a test file (docs/testing.md)",
}
"""Words with a repository prefix that are not paths, and what they are."""

FENCE = re.compile(r"^\s*(```|~~~)")
SPAN = re.compile(r"`([^`]+)`")
PATH = re.compile(r"(?<![\w/.~$-])((?:" + "|".join(REPO_PREFIXES) + r")/[^\s`'\")\],;:]*)")
PLACEHOLDER_PART = re.compile(r"[<{$*]|\.\.\.|…|^[A-Z][A-Z0-9_]+(\.\w+)?$")
PLACEHOLDER = re.compile(r"^(\.\.\.|…|<[^>]*>|[A-Z][A-Z0-9_]*(\.\w+)?([,|][A-Z][A-Z0-9_]*)*)$")
MISSING = ("the following arguments are required", "expected one argument", "expected at least one argument")
BAD_VALUE = re.compile(r"(?:invalid \w+ value|invalid choice): '([^']*)'")


@dataclass(frozen=True)
class Mention:
    """One ``dualarm`` command line or reference of a document."""

    doc: str
    line: int
    words: tuple[str, ...]
    """After ``dualarm``."""
    fenced: bool
    synopsis: bool

    def __str__(self) -> str:
        return f"{self.doc}:{self.line}: dualarm {' '.join(self.words)}"


def shell_commands(text: str) -> list[list[str]] | None:
    """``text`` split into shell commands (words); None if the shell could not split it."""
    lexer = shlex.shlex(text, posix=True, punctuation_chars=";&|")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    try:
        words = list(lexer)
    except ValueError:
        return None
    commands: list[list[str]] = [[]]
    for word in words:
        if word and set(word) <= set(";&|"):
            commands.append([])
        else:
            commands[-1].append(word)
    out = []
    for command in commands:
        while command and (command[0] == "$" or re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", command[0])):
            command = command[1:]
        if command and command[0].endswith("/dualarm"):
            command = ["dualarm", *command[1:]]
        out.append(command)
    return out


def mentions(doc: Path) -> Iterator[Mention]:
    """The ``dualarm`` command lines of ``doc``'s fenced blocks and inline spans."""
    name = doc.relative_to(ROOT).as_posix()
    lines = doc.read_text(encoding="utf-8").splitlines()
    fenced = False
    pending, start = "", 0
    paragraph: list[tuple[int, str]] = []

    def spans() -> Iterator[Mention]:
        text = " ".join(line for _, line in paragraph)
        offsets = []
        position = 0
        for number, line in paragraph:
            offsets.append((position, number))
            position += len(line) + 1
        for match in SPAN.finditer(text):
            content = match.group(1).strip()
            if not re.match(r"^dualarm(\s|$)", content):
                continue
            number = max(n for offset, n in offsets if offset <= match.start())
            synopsis = "[" in content
            for command in shell_commands(content.replace("[", " ").replace("]", " ") if synopsis else content) or []:
                if command[:1] == ["dualarm"]:
                    yield Mention(name, number, tuple(command[1:]), False, synopsis)

    for number, line in enumerate(lines, 1):
        if FENCE.match(line):
            yield from spans()
            paragraph = []
            fenced = not fenced
            continue
        if not fenced:
            if line.strip():
                paragraph.append((number, line))
            else:
                yield from spans()
                paragraph = []
            continue
        if not pending:
            start = number
        pending += line
        if pending.rstrip().endswith("\\"):
            pending = pending.rstrip()[:-1] + " "
            continue
        text, pending = pending, ""
        synopsis = bool(re.search(r"\[-", text))
        commands = shell_commands(text.replace("[", " ").replace("]", " ") if synopsis else text)
        if commands is None:
            if re.match(r"^\s*(\$\s+)?dualarm\s", text):
                yield Mention(name, start, ("<the shell cannot split this line>", text), True, False)
            continue
        for command in commands:
            if command[:1] == ["dualarm"] and not (len(command) > 1 and command[1].endswith(":")):
                yield Mention(name, start, tuple(command[1:]), True, synopsis)
    yield from spans()


ALL_MENTIONS = [m for doc in DOCS for m in mentions(doc)]


class ParseError(Exception):
    """argparse's error message, raised instead of exiting."""


def parse_error(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> str:
    """'' if ``words`` parse, else argparse's message."""

    def error(self: argparse.ArgumentParser, message: str) -> None:
        raise ParseError(f"{self.prog}: {message}")

    saved = argparse.ArgumentParser.error
    argparse.ArgumentParser.error = error  # type: ignore[assignment,method-assign]
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            parser.parse_args(list(words))
    except ParseError as exc:
        return str(exc)
    except SystemExit as exc:  # --help
        return "" if exc.code == 0 else f"exit {exc.code}"
    finally:
        argparse.ArgumentParser.error = saved  # type: ignore[method-assign]
    return ""


def reference_problems(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> list[str]:
    """Verbs of ``words`` that do not exist, and options that are not options of the verb they follow."""
    problems = []
    path = ["dualarm"]
    rest = list(words)
    while rest:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs or rest[0].startswith("-"):
            break
        if rest[0] not in subs[0].choices:
            if len(path) == 1 or not PLACEHOLDER.match(rest[0]):
                problems.append(f"'{' '.join(path)}' has no verb {rest[0]!r}")
            return problems
        path.append(rest.pop(0))
        parser = subs[0].choices[path[-1]]
    if path[1:2] == ["run"]:
        return problems  # after the node: ROS arguments
    for word in rest:
        for part in word.split("|"):
            option = part.split("=", 1)[0]
            if option.startswith("-") and not re.match(r"^-\d", option) and option not in ("-", "--") \
                    and option not in parser._option_string_actions:
                problems.append(f"'{' '.join(path)}' has no option {option}")
    return problems


def problem(parser: argparse.ArgumentParser, mention: Mention) -> str:
    """Why ``mention`` does not match the parser ('' when it does)."""
    if mention.words[:1] == ("<the shell cannot split this line>",):
        return f"the shell cannot split it: {mention.words[1]!r}"
    wrong = reference_problems(parser, mention.words)
    if wrong:
        return "; ".join(wrong)
    if mention.synopsis:
        return ""
    message = parse_error(parser, mention.words)
    if not message or (not mention.fenced and reference_ok(message)):
        return ""
    return message


def reference_ok(message: str) -> bool:
    """Does argparse's ``message`` show an incomplete command line, i.e. a reference?"""
    if any(text in message for text in MISSING):
        return True
    bad = BAD_VALUE.search(message)
    if bad:
        return bool(PLACEHOLDER.match(bad.group(1)))
    if "unrecognized arguments: " in message:
        extra = message.split("unrecognized arguments: ", 1)[1].split()
        return all(PLACEHOLDER.match(word) for word in extra)
    return False


def test_the_docs_hold_the_command_lines() -> None:
    """The extraction finds the documents' command lines (a broken extraction would check nothing)."""
    fenced = [m for m in ALL_MENTIONS if m.fenced]
    assert len(fenced) >= 60 and len(ALL_MENTIONS) >= 250, (len(fenced), len(ALL_MENTIONS))
    docs = {m.doc for m in ALL_MENTIONS}
    assert {"README.md", "docs/ros2.md", "docs/bench.md", "docs/sweep.md"} <= docs


def test_every_dualarm_command_line_parses() -> None:
    parser = build_parser()
    broken = [f"{m}\n    {why}" for m in ALL_MENTIONS if (why := problem(parser, m))]
    assert not broken, f"{len(broken)} dualarm command lines of the docs do not match the parser:\n" + "\n".join(broken)


def test_a_broken_command_line_is_found() -> None:
    """The check fails on what drifts: an unknown verb or option, a bad value, a stray argument."""
    parser = build_parser()
    for words, fenced in ((("launch", "assembly", "--recrd", "out/bag"), True),
                          (("launch", "--recrd"), False),
                          (("lauch", "assembly"), False),
                          (("topic", "hz", "/x", "-w", "1.5"), False),
                          (("report", "out/bag", "out/other"), False),
                          (("launch",), True)):
        assert problem(parser, Mention("doc", 1, words, fenced, False)), words
    for words in (("view", "BAG", "--video"), ("launch", "assembly", "--rate", "HZ"), ("goal", "...", "--wait")):
        assert not problem(parser, Mention("doc", 1, words, False, False)), words


def repository_paths(text: str) -> Iterator[tuple[int, str, str]]:
    """(line, word, the part of it that must exist) of every repository path ``text`` names."""
    for number, line in enumerate(text.splitlines(), 1):
        for match in PATH.finditer(line):
            word = match.group(1).split("::")[0].rstrip(".")
            if word.endswith("**"):
                word = word[:-2].rstrip(".")
            if word in NOT_PATHS:
                continue
            kept = []
            for part in word.split("/"):
                if PLACEHOLDER_PART.search(part.replace("*", "")):
                    break
                kept.append(part)
                if "*" in part:
                    break
            yield number, word, "/".join(kept)


def missing_paths(name: str, text: str) -> list[str]:
    """``name:line: word`` of each repository path of ``text`` that does not exist."""
    missing = []
    for number, word, part in repository_paths(text):
        found = glob.glob(str(ROOT / part), recursive=True) if "*" in part else (ROOT / part).exists()
        if not found:
            missing.append(f"{name}:{number}: {word}")
    return missing


def test_every_repository_path_exists() -> None:
    texts = {doc.relative_to(ROOT).as_posix(): doc.read_text(encoding="utf-8") for doc in DOCS}
    assert len([p for text in texts.values() for p in repository_paths(text)]) >= 250
    missing = [m for name, text in texts.items() for m in missing_paths(name, text)]
    assert not missing, "paths named in the docs that are not in the repository:\n" + "\n".join(missing)


def test_every_launch_file_exists() -> None:
    named = {name for doc in DOCS for name in re.findall(r"\b([\w-]+\.launch\.py)\b", doc.read_text(encoding="utf-8"))}
    assert named and not {n for n in named if not (ROOT / "launch" / n).exists()}


def test_a_moved_file_is_found() -> None:
    """A moved source file and a missing data file are found; placeholders, output and install paths
    and user files are not required."""
    text = ("The relay (`dualarm_control/app/lossy_relay.py`) and config/robots/<name>.yaml, config/robots/*.yaml,\n"
            "test/data/short.yaml, `test/test_bag.py::test_x`, out/bag, install/x/share/dualarm_control/config/no.yaml,\n"
            "my_robot.yaml, docs/NAME.md.\n```\ndualarm launch assembly --params config/hardware/nope.yaml\n```\n")
    assert missing_paths("page.md", text) == ["page.md:1: dualarm_control/app/lossy_relay.py",
                                              "page.md:5: config/hardware/nope.yaml"]


def layout_entries() -> list[str]:
    """The directories of README's Layout block, as repository paths."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("## Layout", 1)[1].split("```", 2)[1]
    entries, stack = [], []
    for line in block.splitlines():
        match = re.match(r"^( {0,8})([\w.-]+)/(?: {2,}|$)", line)
        if match:
            depth = len(match.group(1)) // 2
            stack = [*stack[:depth], match.group(2)]
            entries.append("/".join(stack))
    return entries


def test_readme_layout_follows_the_tree() -> None:
    entries = layout_entries()
    assert not [e for e in entries if not (ROOT / e).is_dir()], "Layout names directories that do not exist"
    packages = [p.parent.relative_to(ROOT).as_posix()
                for top in ("dualarm_control", "dualarm_sim") for p in (ROOT / top).rglob("__init__.py")]
    configs = [p.relative_to(ROOT).as_posix() for p in (ROOT / "config").iterdir() if p.is_dir()]
    wanted = {*packages, *configs, "config", "urdf", "launch", "docs", "test", "test/data"}
    assert not wanted - set(entries), f"README's Layout lacks {sorted(wanted - set(entries))}"


def test_readme_installs_the_makefiles_extras() -> None:
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    extras = re.search(r"^\$\(VENV\)/\.installed:.*?pip install [^\n]*-e '(\.\[[\w,]+\])'", makefile,
                       re.DOTALL | re.MULTILINE)
    assert extras is not None
    assert f"pip install -e '{extras.group(1)}'" in (ROOT / "README.md").read_text(encoding="utf-8")


def test_apt_route_installs_install_requires() -> None:
    """docs/ros2.md's apt route: its ``pip install`` line and its comment name every install_requires."""
    tree = ast.parse((ROOT / "setup.py").read_text(encoding="utf-8"))
    requires = next(ast.literal_eval(node.value) for node in tree.body if isinstance(node, ast.Assign)
                    and any(getattr(t, "id", "") == "INSTALL_REQUIRES" for t in node.targets))
    names = {re.match(r"[\w.-]+", r).group(0).lower() for r in requires}  # type: ignore[union-attr]
    apt = (ROOT / "docs" / "ros2.md").read_text(encoding="utf-8").split("## With ROS 2 Jazzy from apt", 1)[1]
    line = next(line for line in apt.splitlines() if line.startswith("pip install "))
    words = {w.lower() for w in re.findall(r"[\w.-]+", line)}
    aliases = {"pyyaml": "yaml", "pin": "pinocchio"}
    assert not {n for n in names if n not in words and aliases.get(n) not in words}, line
