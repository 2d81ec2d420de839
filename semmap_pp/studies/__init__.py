"""Studies of several runs on one map: knowledge sets compared, seeds' W*s matched."""
