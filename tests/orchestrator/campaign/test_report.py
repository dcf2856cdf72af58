"""The campaign report: the Pareto front and the fitted order against hand values, and the page
itself loaded in headless Chromium (no console errors, every image resolves; screenshot kept in the
test's temporary directory)."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.campaign.report import fit_order, pareto
from tests.orchestrator.campaign.browser import check_page, chromium_path
from tests.orchestrator.campaign.test_spec import SHOCK


def test_pareto_front_keeps_the_runs_nothing_beats_in_both_time_and_error():
    t = np.array([1.0, 2.0, 3.0, 0.5, 2.5, 4.0])
    e = np.array([0.1, 0.05, 0.06, 0.2, 0.01, 0.01])
    # (3.0, 0.06) is beaten by (2.0, 0.05); (4.0, 0.01) by (2.5, 0.01)
    assert list(pareto(t, e)) == [3, 0, 1, 4]


def test_observed_order_of_a_power_law_and_of_too_few_points():
    n = np.array([100.0, 200.0, 400.0, 800.0])
    assert abs(fit_order(n, 3.0 * n ** -1.5) - 1.5) < 1e-12
    assert abs(fit_order(n, 2.0 * n ** -0.9 * (1 + 0.01 * np.array([1, -1, 1, -1]))) - 0.9) < 0.02
    assert np.isnan(fit_order(n[:1], n[:1]))
    assert abs(fit_order(np.array([100.0, 200.0, np.nan]), np.array([1e-2, 5e-3, 1.0])) - 1.0) < 1e-12


@pytest.mark.timeout(300)
def test_the_report_page_loads_without_errors_and_every_image_resolves(tmp_path, run_immerse):
    if chromium_path() is None:
        pytest.skip("no chromium here (.ci/run installs Debian's chromium as root)")
    (tmp_path / "campaign.toml").write_text(f'''
name = "page"
[axes.zones]
values = [100, 200]
"ale.grid.cells" = [[100, 1], [200, 1]]
[[series]]
name = "conforming"
case = "{SHOCK}/conforming"
[report]
error = "l1_density"
error_label = "L1 density error (kg/m^3)"
reference = "exact solution"
resolution = "zones"
''')
    out = tmp_path / "out"
    r = run_immerse("campaign", tmp_path / "campaign.toml", "--out", out)
    assert r.returncode == 0, r.stdout + r.stderr
    shot = tmp_path / "report.png"
    page = check_page(out / "report.html", shot)
    assert page.console_errors == [] and page.broken_images == [], page
    # cost, order, stability map and the finest run's picture, each drawn
    assert len(page.images) == 4 and all(i["naturalWidth"] > 300 for i in page.images), page.images
    assert shot.stat().st_size > 20_000
    assert page.title == "Campaign page"
    # the same page with one chart gone: the check sees it (it is not a check that cannot fail)
    (out / "figures" / "page_order.png").unlink()
    page = check_page(out / "report.html", tmp_path / "broken.png")
    assert page.broken_images and any("page_order.png" in e for e in page.console_errors), page


def test_a_plot_no_run_has_values_for_draws_no_figure(tmp_path):
    """A report plot of a value a chart's runs do not report (the rod's chart asked for the L-block's
    free-flight drift) gives no figure, not an empty one; with values it is drawn."""
    from orchestrator.campaign.report import _chart_vs_resolution

    spec = {"report": {"resolution": "dt"}}
    rows = [{"series": "a", "status": "passed", "level.dt": 0.1, "v": None},
            {"series": "a", "status": "passed", "level.dt": 0.2, "v": None}]
    f = tmp_path / "empty.png"
    assert _chart_vs_resolution(spec, "c", ["a"], rows, lambda r: r["v"], "v", "v", f, fit=False) is None
    assert not f.exists()
    rows[0]["v"], rows[1]["v"] = 1e-3, 4e-3
    assert _chart_vs_resolution(spec, "c", ["a"], rows, lambda r: r["v"], "v", "v", f, fit=False) is not None
    assert f.exists()


def test_a_picture_that_cannot_be_drawn_is_listed_with_its_reason(tmp_path, monkeypatch):
    """The finest run's picture of each series: drawn where it can be; a damaged results.h5 (the
    renderer raising) and a missing one are listed with the run and the reason, not dropped."""
    import orchestrator.view as view
    from orchestrator.campaign.report import _pictures

    rows = [{"series": s, "run": f"{s}-2", "status": "passed", "level.n": 2, "index": 0} for s in ("a", "b", "c")]
    for s in ("a", "b"):
        (tmp_path / "runs" / f"{s}-2" / "out").mkdir(parents=True)
        (tmp_path / "runs" / f"{s}-2" / "out" / "results.h5").write_bytes(b"x")
    picture = tmp_path / "p.png"
    picture.write_bytes(b"png")

    def render(run_out, fields, steps):
        if "b-2" in str(run_out):
            raise OSError("Unable to open file (file signature not found)")
        return [picture]
    monkeypatch.setattr(view, "render", render)
    (tmp_path / "figures").mkdir()
    pics = _pictures(tmp_path, {"report": {"resolution": "n"}}, ["a", "b", "c"], rows, tmp_path / "figures")
    assert pics[0] == ("a", "a, finest run a-2: density at the end time", "picture_a-2.png")
    assert pics[1] == ("b", "b-2: OSError: Unable to open file (file signature not found)", "")
    assert pics[2] == ("c", "c-2: no results.h5 in its output", "")
