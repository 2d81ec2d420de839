"""Argument types shared by the subcommands: each turns bad text into argparse's one-line error."""

from __future__ import annotations

import argparse
import math


def integer(text: str) -> int:
    """Any integer."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None


def positive_int(text: str) -> int:
    """An integer >= 1.

    >>> positive_int("3")
    3
    """
    value = integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """An integer >= 0 (seeds, burn-in lengths)."""
    value = integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def finite(text: str, what: str = "a number") -> float:
    """``text`` as a finite float, else argparse's error naming ``what`` it should be.

    >>> finite("-2e1")
    -20.0
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not {what}: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def non_negative_float(text: str) -> float:
    """A finite number >= 0 (a distance in metres).

    >>> non_negative_float("0.5")
    0.5
    """
    value = finite(text, "a number")
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return value


def seconds(text: str) -> float:
    """A finite number of seconds > 0 (a time budget, an interval).

    >>> seconds("2.5")
    2.5
    """
    value = finite(text, "a number of seconds")
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text}")
    return value
