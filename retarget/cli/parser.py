"""The parts every ``retarget`` command's parser shares: the program name, a parser that
refuses by raising `UsageError` (so `retarget.cli.main` reports it and returns status 2),
the ``--quiet`` option and the argument types."""

from __future__ import annotations

import argparse

import numpy as np

from retarget.custom_layouts import load_layout_file
from retarget.errors import RetargetError
from retarget.layouts import LAYOUTS

__all__ = ["PROG", "Parser", "UsageError", "layout_name", "layout_option", "non_negative_float", "positive_float",
           "positive_int", "quiet_option"]

PROG = "retarget"


class UsageError(Exception):
    """An argparse refusal, carried to `retarget.cli.main` instead of argparse's own exit."""

    def __init__(self, message: str, usage: str):
        super().__init__(message)
        self.usage = usage


class Parser(argparse.ArgumentParser):
    """An argument parser that raises `UsageError` where argparse would print and exit.

    The top-level parser's ``commands`` is its subcommands action (`build_parser` sets it),
    to which a caller adds its own commands (`server.cli` adds ``serve``).
    """

    commands: argparse._SubParsersAction | None = None

    def error(self, message):  # argparse's hook; the default prints and exits
        raise UsageError(message, self.format_usage())


def quiet_option() -> Parser:
    """The parent parser of the commands that draw progress bars: ``-q/--quiet``."""
    quiet = Parser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true",
                       help="hide the progress bars on stderr")
    return quiet


def layout_option(parser, what: str = "landmark layout") -> None:
    """``--layout NAME|L.json``, for the commands that read a landmarks JSON: which layout its
    points follow when the JSON does not say: a built-in one, or a custom layout file."""
    parser.add_argument("--layout", type=layout_name, metavar="NAME|L.json",
                        help=f"{what}: a built-in layout ({', '.join(LAYOUTS)}) or a custom layout "
                        f"file ('{PROG} layouts new'); default: the landmarks JSON's \"layout\"")


def layout_name(text: str) -> str:
    """An argparse type: a built-in layout's name, or the (registered) name of the custom
    layout in a layout file."""
    if text in LAYOUTS:
        return text
    if not text.endswith(".json"):
        raise argparse.ArgumentTypeError(
            f"invalid choice: {text!r} (choose from {', '.join(LAYOUTS)}, or a custom layout .json)")
    try:
        return load_layout_file(text).name
    except RetargetError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _number(cast, *, minimum: float, strict: bool, what: str):
    """An argparse type: `cast(text)`, finite and > `minimum` (`strict`) or >= it."""
    def parse(text: str):
        try:
            value = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not np.isfinite(value) or value < minimum or (strict and value == minimum):
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value
    return parse


positive_float = _number(float, minimum=0.0, strict=True, what="a positive number")
positive_int = _number(int, minimum=1, strict=False, what="a positive integer")
non_negative_float = _number(float, minimum=0.0, strict=False, what="a finite number >= 0")
