"""The reliability diagram (`semmap eval --figure`, report.html's calibration section) plots the
reliability table it is given: per kind, each bin's mean probability and fraction right, its claims
as bars and marker areas, the ECE in the title; and report.html takes it as its calibration section."""

import io

import numpy as np
import pytest
from PIL import Image

from semmap_pp.evaluate.calibration import KINDS, calibration_summary, reliability
from semmap_pp.outputs.figures import RELIABILITY_COLOUR, reliability_figure, reliability_png
from semmap_pp.outputs.report import (CALIBRATION_BEGIN, CALIBRATION_END, calibration_section,
                                      with_calibration)


def claims(seed: int, n: int):
    """``n`` claims whose truth comes less often than their probability says (overconfident)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(0.0, 1.0, n)
    return list(p), list(rng.uniform(0.0, 1.0, n) < p ** 2)


@pytest.fixture(scope="module")
def table():
    return calibration_summary([{"units": claims(0, 300), "types": claims(1, 40), "doors": ([], [])}])


def panels(fig):
    """{kind: (reliability axes, claims-per-bin axes)}, the axes in the order they were added."""
    axes = fig.axes
    return {ax.get_gid(): (ax, axes[i + 1]) for i, ax in enumerate(axes) if ax.get_gid() in KINDS}


def test_the_diagram_plots_the_reliability_table(table):
    fig = reliability_figure(table, "a title")
    drawn = panels(fig)
    assert list(drawn) == list(KINDS)
    for kind in ("units", "types"):
        top, bottom = drawn[kind]
        bins = np.array(table[kind]["bins"], dtype=float)
        lo, hi, n, conf, acc = bins.T
        line, = [ln for ln in top.get_lines() if ln.get_gid() == "reliability"]
        np.testing.assert_array_equal(line.get_xdata(), conf)
        np.testing.assert_array_equal(line.get_ydata(), acc)
        markers, = [c for c in top.collections if c.get_gid() == "claims"]
        np.testing.assert_array_equal(markers.get_offsets(), np.column_stack([conf, acc]))
        sizes = markers.get_sizes()
        assert np.array_equal(np.argsort(sizes, kind="stable"), np.argsort(n, kind="stable"))  # area follows claims
        bars = bottom.patches
        np.testing.assert_array_equal([b.get_height() for b in bars], n)
        np.testing.assert_allclose([b.get_x() for b in bars], lo)
        np.testing.assert_allclose([b.get_x() + b.get_width() for b in bars], hi)
        assert top.get_title() == f"{kind}: {table[kind]['claims']} claims, ECE {table[kind]['ece']:.4f}"
        assert line.get_color() == RELIABILITY_COLOUR[kind]
        diagonal = [ln for ln in top.get_lines() if ln.get_gid() is None]
        assert any(list(ln.get_xdata()) == [0, 1] and list(ln.get_ydata()) == [0, 1] for ln in diagonal)
    top, bottom = drawn["doors"]                       # no claims: the diagonal, no bins
    assert top.get_title() == "doors: no claims" and not bottom.patches
    assert not [ln for ln in top.get_lines() if ln.get_gid() == "reliability"]
    assert fig._suptitle.get_text() == "a title"


def test_the_table_behind_the_diagram_is_the_reliability_of_the_claims(table):
    """What the diagram draws is :func:`reliability` of the claims, rounded as --json gives it."""
    p, y = claims(0, 300)
    t = reliability(p, y)
    assert table["units"]["bins"] == [[b.lo, b.hi, b.n, round(b.confidence, 4), round(b.accuracy, 4)]
                                      for b in t.bins if b.n]
    assert table["units"]["ece"] == round(t.ece, 4) > 0.05          # overconfident: far from the diagonal


def test_the_diagram_is_a_png_and_its_title_is_text(table):
    data = reliability_png(table, "run $HOME/x against \udcff floor")   # no mathtext, no encoding error
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    image = Image.open(io.BytesIO(data))
    image.verify()
    w, h = Image.open(io.BytesIO(data)).size
    assert 1000 <= w <= 1400 and 400 <= h <= 700
    rgb = np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).reshape(-1, 3).astype(int)
    for kind in ("units", "types"):                    # each kind drawn in its colour
        c = np.array([int(RELIABILITY_COLOUR[kind][i:i + 2], 16) for i in (1, 3, 5)])
        assert np.count_nonzero(np.abs(rgb - c).sum(axis=1) < 30) > 200, kind


def test_the_report_takes_the_section_in_its_place_once(table):
    page = ("<nav><a href=\"#spread\">Posterior spread</a><a href=\"#convergence\">Convergence</a></nav>"
            f"<h2 id=\"spread\">s</h2>{CALIBRATION_BEGIN}{CALIBRATION_END}\n<h2 id=\"convergence\">c</h2>")
    png = reliability_png(table)
    section = calibration_section(table, png, run="<run>", truth="<b>floor</b>")
    once = with_calibration(page, section)
    assert once.index('id="spread"') < once.index('id="calibration"') < once.index('id="convergence"')
    assert once.count('href="#calibration"') == 1 and once.count('id="calibration"') == 1
    assert "&lt;b&gt;floor&lt;/b&gt;" in once and "<b>floor</b>" not in once
    assert "<td>units</td><td>[0.0, 0.1)</td>" in once.replace('<td class="num">', "<td>")
    again = with_calibration(once, calibration_section(table, png, run="r", truth="second"))
    assert again.count('id="calibration"') == 1 and "second" in again and "&lt;b&gt;floor" not in again
    old = page.replace(CALIBRATION_BEGIN + CALIBRATION_END, "")    # a report without the place
    placed = with_calibration(old, section)
    assert placed.index('id="calibration"') < placed.index('id="convergence"')
    with pytest.raises(ValueError, match="not a report.html"):
        with_calibration("<html>x</html>", section)
