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
