"""Every example in every `graspguide ... --help` is a command a user can paste: it parses
as shell (shlex), each line break in it is escaped, and its `graspguide` command line is
accepted by the command's own parser."""

from __future__ import annotations

import argparse
import shlex

import pytest

from graspguide.cli import build_parser


def _parsers(p: argparse.ArgumentParser, path: tuple[str, ...]):
    yield path, p
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


ALL = list(_parsers(build_parser(), ("graspguide",)))


def _examples(help_text: str) -> list[list[str]]:
    """The examples section's examples, each as its physical lines: an example goes on
    while its line ends in a backslash or a quotation is open."""
    lines = help_text.splitlines()
    try:
        start = lines.index("examples:") + 1
    except ValueError:
        return []
    examples: list[list[str]] = []
    current: list[str] = []
    for line in lines[start:]:
        if not line.strip():
            break
        current.append(line)
        text = "\n".join(current)
        if text.endswith("\\"):
            continue
        try:
            shlex.split(text, comments=True)
        except ValueError:  # an open quotation: the example goes on
            continue
        examples.append(current)
        current = []
    assert not current, f"an example never ends: {current}"
    return examples


def _lost_line_break(line: str) -> bool:
    """Spaces in a run inside a line (outside a trailing # comment): the mark of a line
    break whose backslash was lost, which the source's string joins with the next line."""
    code = line.strip().split(" #", 1)[0].rstrip()
    return "   " in code


def _graspguide_args(tokens: list[str]) -> list[str]:
    i = tokens.index("graspguide")
    args = []
    for tok in tokens[i + 1 :]:
        if tok in ("|", "&&", ";", "||", ">"):
            break
        args.append(tok)
    return args


@pytest.mark.parametrize("path,parser", ALL, ids=[" ".join(p) for p, _ in ALL])
def test_every_help_example_parses_as_shell_and_as_the_command(path, parser):
    for example in _examples(parser.format_help()):
        for line in example:
            assert not _lost_line_break(line), (
                f"{' '.join(path)} --help: a line break lost its backslash: {line.strip()!r}"
            )
        text = "\n".join(example)
        # the shell drops an escaped line break (shlex would keep the newline)
        tokens = shlex.split(text.replace("\\\n", " "), comments=True)
        assert "graspguide" in tokens, f"{' '.join(path)} --help: {text!r} runs no graspguide"
        argv = _graspguide_args(tokens)
        try:
            build_parser().parse_args(argv)
        except SystemExit as e:  # argparse's error: the example is not a valid command
            pytest.fail(f"{' '.join(path)} --help example {text!r} does not parse: exit {e}")


def test_the_examples_are_found():
    """The test above checks something: the commands with examples have them parsed."""
    found = {" ".join(p): len(_examples(parser.format_help())) for p, parser in ALL}
    assert found["graspguide stream"] == 3
    assert found["graspguide trial"] == 5
