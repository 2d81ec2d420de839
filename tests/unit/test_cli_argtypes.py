"""The shared argument types of the subcommands: good text parsed, bad text one argparse error."""

from __future__ import annotations

import argparse

import pytest

from semmap_pp.cli import argtypes


@pytest.mark.parametrize("parse, text, value", [
    (argtypes.integer, "-3", -3), (argtypes.positive_int, "1", 1), (argtypes.non_negative_int, "0", 0),
    (argtypes.non_negative_float, "0", 0.0), (argtypes.non_negative_float, "2.5e-1", 0.25),
    (argtypes.finite, "-2e1", -20.0), (argtypes.seconds, "0.5", 0.5), (argtypes.seconds, "1e3", 1000.0),
])
def test_good_text_is_parsed(parse, text, value):
    assert parse(text) == value


@pytest.mark.parametrize("parse, text, message", [
    (argtypes.integer, "1.5", "not an integer: '1.5'"),
    (argtypes.positive_int, "0", "must be >= 1, got 0"),
    (argtypes.non_negative_int, "-1", "must be >= 0, got -1"),
    (argtypes.finite, "1,5", "not a number: '1,5'"),
    (argtypes.finite, "inf", "must be a finite number, got inf"),
    (argtypes.non_negative_float, "x", "not a number: 'x'"),
    (argtypes.non_negative_float, "-0.1", "must be a finite number >= 0, got -0.1"),
    (argtypes.non_negative_float, "nan", "must be a finite number, got nan"),
    (argtypes.seconds, "soon", "not a number of seconds: 'soon'"),
    (argtypes.seconds, "0", "must be a positive number of seconds, got 0"),
    (argtypes.seconds, "-inf", "must be a finite number, got -inf"),
])
def test_bad_text_is_one_argparse_error(parse, text, message):
    with pytest.raises(argparse.ArgumentTypeError) as err:
        parse(text)
    assert str(err.value) == message


@pytest.mark.parametrize("text", ["-2e1", "-2.", "-2.5E-1", "-.5", "-3"])
def test_negative_numbers_in_every_spelling_are_arguments_not_options(text):
    from semmap_pp.cli import build_parser

    args = build_parser().parse_args(["edit", "m.yaml", "w.json", "--out", "o", "--cut", "1", text,
                                      "2", "3", "4", "--wall", "2", "5", text])
    assert [(e.kind, e.args) for e in args.edits] == [("cut", ("1", text, "2", "3", "4")),
                                                      ("wall", ("2", "5", text))]


@pytest.mark.parametrize("text", ["-2.5,3", "-1e1,-2", "-.5,-.5"])
def test_a_point_whose_x_is_negative_is_an_argument(text):
    from semmap_pp.cli import build_parser

    args = build_parser().parse_args(["route", "w.json", text, "1"])
    assert (args.start, args.goal) == (text, "1")


@pytest.mark.parametrize("text", ["-x", "-2x", "--2e1", "-e1", "-2,x", "-2,3,4"])
def test_what_is_no_number_is_still_an_unknown_option(text, capsys):
    from semmap_pp.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["edit", "m.yaml", "w.json", "--out", "o", "--wall", "2", "5", text])
