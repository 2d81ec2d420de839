"""Argument types shared by the subcommands: each turns bad text into argparse's one-line error."""

from __future__ import annotations

import argparse
import math

from semmap_pp.sampler.sampling import MAX_N_INNER, MAX_SEED


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




def seed(text: str) -> int:
    """A seed in ``[0, MAX_SEED]``.

    >>> seed("7")
    7
    """
    value = non_negative_int(text)
    if value > MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_SEED}, got {text[:24]}"
                                         f"{'...' if len(text) > 24 else ''}")
    return value


def n_inner(text: str) -> int:
    """Kernels per draw, in ``[1, MAX_N_INNER]``."""
    value = positive_int(text)
    if value > MAX_N_INNER:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_N_INNER:,} kernels per draw, got {value:,}")
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


def bag_time(text: str) -> float | str:
    """``last``, or a finite number of seconds >= 0 since a bag's start (``--at``).

    >>> bag_time("last"), bag_time("12.5")
    ('last', 12.5)
    """
    if text.strip().lower() == "last":
        return "last"
    value = finite(text, "'last' or a number of seconds")
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 'last' or seconds >= 0 since the bag's start, got {text}")
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
