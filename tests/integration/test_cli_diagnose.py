"""`semmap diagnose DIR`: re-reads trace.nc; exit 0 when converged, 1 when not, 2 without a trace."""

import json

import numpy as np
import pytest

from semmap_pp.cli import main
from semmap_pp.sampler.diagnostics import to_datatree, write_trace


def write_run(path, shift=0.0, seed=0):
    """A trace.nc of 4 chains x 300 draws; ``shift`` moves chain 0 of the log posterior away."""
    rng = np.random.default_rng(seed)
    lp = rng.normal(-100.0, 1.0, size=(4, 300))
    lp[0] += shift
    summaries = {"log_posterior": lp, "n_units": rng.normal(10.0, 1.0, size=(4, 300))}
    stats = {"accept": np.full((4, 300), 0.25), "accept_add_remove": np.full((4, 300), 0.5)}
    path.mkdir()
    write_trace(to_datatree(summaries, sample_stats=stats, attrs={"rules": "table3.lp", "seed": 7}),
                path / "trace.nc")
    return path


def test_converged_run_exits_0_and_prints_the_table(tmp_path, capsys):
    d = write_run(tmp_path / "ok")
    assert main(["diagnose", str(d)]) == 0
    out = capsys.readouterr().out
    assert "converged" in out and "NOT converged" not in out
    assert "rules table3.lp" in out and "seed 7" in out
    assert "posterior spread" in out and "acceptance" in out and "add_remove 0.500" in out


def test_stuck_chain_exits_1(tmp_path, capsys):
    d = write_run(tmp_path / "stuck", shift=5.0)
    assert main(["diagnose", str(d / "trace.nc")]) == 1      # the trace file itself works too
    assert "NOT converged" in capsys.readouterr().out


def test_json_has_rhat_ess_and_spread(tmp_path, capsys):
    d = write_run(tmp_path / "j", shift=5.0)
    assert main(["diagnose", str(d), "--json"]) == 1
    doc = json.loads(capsys.readouterr().out)
    q = doc["convergence"]["quantities"]["log_posterior"]
    assert doc["convergence"]["ok"] is False and q["rhat"] > 1.05 and q["ess_bulk"] > 0
    s = doc["spread"]["n_units"]
    assert s["q05"] < s["q50"] < s["q95"] and s["sd"] == pytest.approx(1.0, abs=0.1)


def test_missing_trace_is_a_user_error(tmp_path, capsys):
    assert main(["diagnose", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "no trace file here" in err and err.count("\n") == 1


@pytest.mark.parametrize("shift, chains", [(5.0, [1]), (-5.0, [2, 3, 4]), (0.0, [1, 2, 3, 4])])
def test_the_spread_pools_only_the_chains_in_the_best_chains_mode(tmp_path, capsys, shift, chains):
    # Chain 1 five standard deviations above (or below) the other three: a separate mode. The
    # spread summarises the draws of the best chain's mode, as the run's figures do.
    d = write_run(tmp_path / "m", shift=shift)
    main(["diagnose", str(d), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["spread_chains"] == chains
    lp = doc["spread"]["log_posterior"]
    assert lp["mean"] == pytest.approx(-100.0 + (shift if chains == [1] else 0.0), abs=0.2)
    assert lp["sd"] == pytest.approx(1.0, abs=0.1)          # pooled across modes it would be ~2.4
    main(["diagnose", str(d)])
    heading = {1: "(chain 1's draws: the best chain's mode)", 3: "(chains 2, 3, 4's draws: the best chain's mode)",
               4: "(all chains and draws)"}[len(chains)]
    assert "posterior spread of the summaries " + heading in capsys.readouterr().out
