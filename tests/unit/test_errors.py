import pickle

import pytest

from semmap_pp.errors import MapError, RuleError, SemmapError


@pytest.mark.parametrize("err", [
    SemmapError("a.yaml", "bad\nthing"),
    MapError("m.pgm", "truncated"),
    RuleError("r.lp", "unsafe variable X", 3, 7),
    SemmapError(None, "no file"),
])
def test_errors_are_one_line_and_survive_pickling(err):
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is type(err) and str(back) == str(err)
    assert "\n" not in str(err)


def test_position_format():
    assert str(RuleError("r.lp", "x", 3, 7)) == "r.lp:3:7: x"
    assert str(MapError("m.pgm", "y")) == "m.pgm: y"


def test_after_ctrl_c_a_half_built_objects_finalizer_prints_nothing(capfd, monkeypatch):
    """An interrupt inside a library's constructor (a clingo AST node) leaves an object whose
    ``__del__`` fails at its collection; after ``quiet_finalizers`` Python prints no traceback."""
    import gc
    import sys

    from semmap_pp.cli import quiet_finalizers

    class HalfBuilt:
        def __del__(self):
            raise AttributeError("no attribute: _rep")

    monkeypatch.setattr(sys, "unraisablehook", sys.__unraisablehook__)
    HalfBuilt()
    gc.collect()
    assert "Traceback" in capfd.readouterr().err          # what Ctrl-C printed before
    quiet_finalizers()
    HalfBuilt()
    gc.collect()
    assert capfd.readouterr().err == ""


def test_the_command_sets_the_heap_aside_before_the_teardown_whatever_its_end(capsys):
    """console_main (the `semmap` script, `python -m semmap_pp`) returns main's status, and leaves
    every object frozen so that the interpreter's teardown does not collect over the heap, also
    after an error."""
    import gc

    from semmap_pp.cli import console_main

    try:
        for argv, status in ((["rules", "list"], 0), (["map", "/nonexistent/map.yaml", "--out", "x"], 2)):
            gc.unfreeze()
            assert gc.get_freeze_count() == 0
            assert console_main(argv) == status
            assert gc.get_freeze_count() > 0
        assert "semmap: error:" in capsys.readouterr().err
    finally:
        gc.unfreeze()


def test_ctrl_c_while_the_commands_are_imported_is_one_line(capsys, monkeypatch):
    """Building the parser imports every command's module (a second on a cold start): Ctrl-C
    then is `semmap: interrupted` and exit 130, as later, not a traceback."""
    import semmap_pp.cli as cli

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["rules", "list"]) == 130
    assert capsys.readouterr().err == "semmap: interrupted\n"
