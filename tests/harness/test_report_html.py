"""report.html (harness/report/html.py): self-contained, holds every row and family, and
-- in headless Chromium, when one is installed (make setup-browser) -- draws every chart
without console errors, reacts to the family toggle, and renders a non-blank screenshot."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness import build_report
from contactbench.harness.report import core as rp
from contactbench.harness.report import html as html_report
from contactbench.harness.report.browser import browser_missing, check_page
from contactbench.harness.report.style import MAX_SERIES, SolverStyles, family_panels, panels_note

from tests.helpers import fabricate_table, report_row, write_out


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame]:
    df = fabricate_table()
    # a solver registered from outside, with its own family (docs' example: family = "other")
    extra = df[(df["scene"] == "paper-sweep") & (df["solver"] == "nnls")].assign(
        solver="my-solver", base_solver="my-solver", family="other")
    df = pd.concat([df, extra], ignore_index=True)
    out = write_out(tmp_path_factory.mktemp("html"), df)
    build_report(out)
    return out / "report.html", df


def _data(html: str) -> dict:
    m = re.search(r'<script id="report-data" type="application/json">(.*?)</script>', html, re.S)
    assert m, "the page's data block is missing"
    return json.loads(m.group(1))


def test_page_is_one_offline_file_with_every_row_and_family(page: tuple[Path, pd.DataFrame]) -> None:
    path, df = page
    text = path.read_text()
    assert "<script src" not in text and "<link" not in text  # nothing fetched: scripts inlined
    assert "Plotly" in text and len(text) > 1_000_000  # plotly.js is inside
    data = _data(text)
    attempted = df[df["status"] != "skipped"]
    assert len(data["rows"]) == len(attempted)
    fams = {f["name"]: {s["name"] for s in f["solvers"]} for f in data["families"]}
    assert set(fams) == set(df["family"].replace("", "other"))
    assert "my-solver" in fams["other"]
    row = data["rows"][0]
    for key in ("inst", "st", "n", "kkt", "perr", "lerr", "t", "it", "stt"):  # the hover's fields
        assert key in row
    assert set(data["pp"]) >= {"paper-sweep", "counterexample"} and set(data["sgm"]) == set(df["scene"])


def test_fig6_gives_the_page_its_k_colours_in_k_order(page: tuple[Path, pd.DataFrame]) -> None:
    """The gp-k-sweep scene's variants, one family's seven shades otherwise, are drawn on the
    page in the PNG's colours: one per K, in the order of K."""
    from contactbench.harness.report.sections.paper import k_of

    path, df = page
    (chart,) = [c for c in _data(path.read_text())["rowcharts"] if c["scene"] == "gp-k-sweep"]
    solvers = [s for s, _ in chart["colors"]]
    k = {r["solver"]: k_of(r) for _, r in df[df["scene"] == "gp-k-sweep"].iterrows()}
    assert set(solvers) == set(k) and [k[s] for s in solvers] == sorted(k.values())
    assert len({c for _, c in chart["colors"]}) == len(solvers)


def test_solver_colours_are_fixed_and_a_family_shares_a_hue() -> None:
    import colorsys

    fams = {**{f"p{i}": "paper" for i in range(12)}, **{f"f{i}": "fast" for i in range(5)}, "x": ""}
    st = SolverStyles(fams, lambda s: (s,))
    assert st.family("x") == "other"
    again = SolverStyles(dict(reversed(list(fams.items()))), lambda s: (s,))
    assert all(st.color(s) == again.color(s) for s in fams)  # independent of the order met
    hues = {f: [colorsys.rgb_to_hls(*st.color(s))[0] for s in fams if st.family(s) == f] for f in ("paper", "fast")}
    assert max(hues["paper"]) - min(hues["paper"]) < 0.2 and max(hues["fast"]) - min(hues["fast"]) < 0.2
    assert abs(np.mean(hues["paper"]) - np.mean(hues["fast"])) > 0.15
    assert len({st.color(s) for s in fams}) == len(fams)


def test_neighbours_in_a_family_differ_in_shade_and_dash() -> None:
    """Ten shades of one hue are hard to tell apart as lines: neighbours in a family differ
    in lightness and in line dash too (a panel draws at most MAX_SERIES of them)."""
    import colorsys

    st = SolverStyles({f"q{i:02d}": "qp" for i in range(10)}, lambda s: (s,))
    names = [f"q{i:02d}" for i in range(10)]
    for a, b in zip(names, names[1:]):
        assert st.dash(a) != st.dash(b)
        assert abs(colorsys.rgb_to_hls(*st.color(a))[1] - colorsys.rgb_to_hls(*st.color(b))[1]) > 0.05
    assert len({(st.color(s), st.dash(s)) for s in names}) == 10 and st.dash("unknown") == "-"


def _lab(rgb: tuple[float, float, float]) -> np.ndarray:
    """CIE L*a*b* (D65) of an sRGB colour."""
    c = np.asarray(rgb, dtype=float)
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]) @ c
    x, y, z = xyz / np.array([0.95047, 1.0, 1.08883])
    f = lambda t: np.cbrt(t) if t > 0.008856 else 7.787 * t + 16 / 116  # noqa: E731
    return np.array([116 * f(y) - 16, 500 * (f(x) - f(y)), 200 * (f(y) - f(z))])


def test_two_families_never_share_a_colour() -> None:
    """Every solver of the project (peers included), three external programs and three solvers
    registered from outside: two solvers of different families at least 10 apart in CIE
    L*a*b* (2 apart is one colour to the eye),
    two of one family at least 4 apart (markers tell those apart too)."""
    from itertools import combinations

    from contactbench.solvers.registry import all_solvers

    fams = {name: s.family for name, s in all_solvers().items() if s.family != "test"}  # not the tests' own
    fams.update({f"ext{i}": "external" for i in range(3)} | {f"mine{i}": "other" for i in range(3)})
    st = SolverStyles(fams, rp.natural_key)
    lab = {s: _lab(st.color(s)) for s in fams}
    dist = {(a, b): float(np.linalg.norm(lab[a] - lab[b])) for a, b in combinations(fams, 2)}
    cross = min((d, p) for p, d in dist.items() if st.family(p[0]) != st.family(p[1]))
    within = min((d, p) for p, d in dist.items() if st.family(p[0]) == st.family(p[1]))
    assert cross[0] >= 10.0, cross
    assert within[0] >= 4.0, within


def test_panels_hold_at_most_ten_series_and_cover_every_solver() -> None:
    solvers = [f"s{i:02d}" for i in range(33)]
    fam = {s: ("paper", "fast", "qp", "wrapper", "other")[i % 5] if i < 30 else "qp" for i, s in enumerate(solvers)}
    panels = family_panels(solvers, fam.get, best={"paper": "s00", "fast": "s01"})
    assert panels[0].title == "best of each family" and panels[0].solvers == ("s00", "s01")
    assert all(len(p.solvers) <= MAX_SERIES for p in panels)
    assert {s for p in panels if p.family for s in p.solvers} == set(solvers)
    assert "family other" in [p.title for p in panels]  # an outside family is drawn, not dropped
    note = panels_note(panels)
    assert "other (6)" in note and "light grey" in note
    assert family_panels(solvers[:10], fam.get) [0].solvers == tuple(solvers[:10])


@pytest.mark.slow
def test_the_page_renders_in_headless_chromium(page: tuple[Path, pd.DataFrame], tmp_path: Path) -> None:
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    path, _ = page
    shot = tmp_path / "shot.png"
    check = check_page(path, shot, family="paper")
    assert check.console_errors == []
    assert check.charts == check.expected_charts
    assert check.empty_charts == []  # every chart with a point to draw shows it (the counterexample's bars too)
    # scenes of the fabricated table: paper-sweep, greedy, gp-k-sweep, counterexample, hertz
    assert check.charts >= 5 * 3
    assert check.traces_after_toggle is not None and check.traces_after_toggle < check.traces
    assert check.load_s < 60.0  # a generous limit, not a speed claim
    from matplotlib.image import imread

    img = imread(shot)
    assert img.shape[0] > 500 and img.shape[1] > 800
    flat = img[..., :3].reshape(-1, 3)
    assert flat.std() > 0.05  # not blank
    assert len(np.unique((flat * 255).astype(np.uint8), axis=0)) > 50


def crowded_table() -> pd.DataFrame:
    """The fabricated table with 14 more solvers on paper-sweep (copies of nnls's rows, each
    a little slower than the last, in the families qp and fast; the last with a long name, as a
    solver with its parameters): 20 solvers in one scene."""
    df = fabricate_table()
    base = df[(df["scene"] == "paper-sweep") & (df["solver"] == "nnls")]
    names = [f"x{k:02d}" for k in range(13)] + ["x13 coarse=mean h=2 from 16 levels, warm-started, tol 1e-9"]
    extra = [base.assign(solver=name, base_solver=name, family=("qp", "fast")[k % 2],
                         solve_time_s=base["solve_time_s"] * (1.5 + 0.1 * k)) for k, name in enumerate(names)]
    return pd.concat([df, *extra], ignore_index=True)


def test_a_crowded_scene_leads_with_the_best_of_each_family(tmp_path: Path) -> None:
    """``scene_leads``: each family's best by SGM first, one per family, then the rest by SGM."""
    ctx = rp.ReportContext(tmp_path, crowded_table(), {})
    lead = html_report.scene_leads(ctx, html_report.scene_summaries(ctx))["paper-sweep"]
    fams = [ctx.family(s) for s in lead["order"][:lead["best"]]]
    assert len(fams) == len(set(fams)) == lead["best"]
    assert set(fams) == {ctx.family(s) for s in lead["order"]}
    firsts = lead["order"][:lead["best"]]
    slowest = next(s for s in lead["order"] if s.startswith("x13"))
    assert "x00" in firsts and not {"x02", slowest} & set(firsts)  # qp's fastest copy leads it
    assert lead["order"].index("x01") < lead["order"].index("x03") < lead["order"].index(slowest)
    assert lead["profile"] == "high" and len(lead["order"]) == 20


@pytest.mark.slow
def test_a_crowded_chart_draws_at_most_max_series(tmp_path: Path) -> None:
    """20 solvers on a scene: each chart draws at most ``MAX_SERIES`` series (the others in
    its legend), none is empty, and unticking a drawn family brings the next ones in."""
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    out = write_out(tmp_path, crowded_table())
    build_report(out)
    check = check_page(out / "report.html", family="qp")
    assert check.console_errors == [] and check.empty_charts == []
    assert check.most_drawn <= MAX_SERIES + 1  # + the counterexample's reference line
    assert 0 < check.longest_legend <= 45  # a long name elided, so that the plot keeps its width
    assert check.traces_after_toggle is not None and check.traces_after_toggle > 0


@pytest.mark.slow
def test_a_scene_of_one_family_draws_max_series_not_one(tmp_path: Path) -> None:
    """14 solvers of one family on one scene at one profile: its charts draw ``MAX_SERIES`` of
    them (the best of the family first, then the next by SGM), not the family's best alone."""
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    df = fabricate_table()
    base = df[(df["scene"] == "paper-sweep") & (df["solver"] == "nnls") & (df["profile"] == "high")]
    one = pd.concat([base.assign(solver=f"q{k:02d}", base_solver=f"q{k:02d}", family="qp",
                                 solve_time_s=base["solve_time_s"] * (1.0 + 0.1 * k)) for k in range(14)],
                    ignore_index=True)
    out = write_out(tmp_path, one)
    build_report(out)
    check = check_page(out / "report.html")
    assert check.empty_charts == [] and check.most_drawn == MAX_SERIES


def test_a_stored_field_gives_the_field_pictures_and_kappa(tmp_path: Path) -> None:
    """save_field keeps a solved top step (and only that); the report draws the surface,
    pressure and gap from it and fits kappa on the table's load-area points."""
    from contactbench.harness.table.fields import FIELD_MAX_SIDE, block_reduce, field_name, load_field, save_field
    from contactbench.harness.judging import judge
    from contactbench.harness.report.sections.fields import PERSSON_KAPPA, fit_kappa
    from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
    from contactbench.problems.surfaces import rmd_surface_n
    from contactbench.solvers.base import SolverSettings
    from contactbench.solvers.registry import load_solver

    surf = rmd_surface_n(32, 0.7, seed=1)
    builder = InstanceBuilder(surf, E=1.0)
    dmax = paper_max_displacement(surf)
    arrays = tmp_path / "arrays" / "x.npz"
    rows = []
    for k, d in enumerate(np.linspace(0.1, 1.0, 4) * dmax):
        inst = builder.build(float(d))
        p = load_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-10)).p
        status = judge(inst, p, True, 1e-8).status
        assert status == "solved"
        kept = save_field(str(arrays), "paper-sweep", "s1", inst, p, k, 4, "nnls", status)
        assert (kept is not None) == (k == 3)  # the top step only
        rows.append(dict(scene="paper-sweep", instance="s1", step=k, n=inst.n, N=32, solver="nnls", family="paper",
                         delta=float(d), dim_load=inst.dimensionless_load(p), contact_fraction=inst.contact_fraction(p),
                         solve_time_s=0.01, load=inst.load(p)))
    assert save_field(str(arrays), "paper-sweep", "s1", inst, p, 3, 4, "nnls", "inaccurate") is None
    f = load_field(tmp_path / "arrays" / field_name("paper-sweep", "s1", 3), "paper-sweep", "s1")
    assert f.heights.shape == (32, 32) and f.contact.sum() == np.count_nonzero(inst.contact_mask(p))
    assert np.nanmin(f.gap[~f.contact]) >= -1e-6 * float(np.ptp(surf.heights))  # a gap is never negative
    assert abs(f.pressure.sum() * f.spacing**2 - inst.load(p)) < 1e-6 * inst.load(p)
    assert block_reduce(np.ones((2 * FIELD_MAX_SIDE,) * 2)).shape == (FIELD_MAX_SIDE, FIELD_MAX_SIDE)
    assert max(block_reduce(np.ones((2 * FIELD_MAX_SIDE + 3,) * 2)).shape) <= FIELD_MAX_SIDE
    x = np.array([1e-4, 2e-4, 4e-4])
    assert abs(fit_kappa(x, PERSSON_KAPPA / 0.5 * x, 0.5).kappa - PERSSON_KAPPA) < 1e-12
    from contactbench.harness.table.schema import ALL_COLUMNS

    df = pd.DataFrame([report_row(**r) for r in rows], columns=list(ALL_COLUMNS))
    text = build_report(write_out(tmp_path, df), html=False).read_text()
    assert "## The contact fields" in text and "figures/field-paper-sweep-s1-k3.png" in text
    assert "figures/load-area.png" in text and "figures/traces-" not in text  # no traces stored
    kappa = fit_kappa(df["dim_load"].to_numpy(), df["contact_fraction"].to_numpy(), surf.rms_slope()).kappa
    assert "| paper-sweep | s1 | 4 |" in text and rp.fmt_num(kappa) in text


@pytest.mark.slow
def test_a_long_solver_name_wraps_in_the_picker_and_the_sgm_table(tmp_path: Path) -> None:
    """At 1400 px, the crowded scene's long name (a solver with its parameters) is shown whole in
    the picker (wrapped, not cut to a stub like its neighbours') and its SGM table cell wraps, so
    that the table fits its box."""
    from contactbench.harness.report.browser import load_page, open_driver

    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    out = write_out(tmp_path, crowded_table())
    build_report(out)
    driver = open_driver(1400, 1000)
    try:
        load_page(driver, out / "report.html")
        got = driver.execute_script("""
          const nav = document.getElementById('picker'), edge = nav.getBoundingClientRect().right;
          const cut = [...nav.querySelectorAll('label')].filter(l => l.getBoundingClientRect().right > edge + 1)
            .map(l => l.textContent).concat(nav.scrollWidth > nav.clientWidth + 1 ? ['(the picker scrolls sideways)'] : []);
          const wide = [...document.querySelectorAll('.tablebox')].filter(b => b.querySelector('table.sgm') &&
            b.closest('section.scene')).map(b => [b.scrollWidth, b.clientWidth]).filter(([s, c]) => s > c + 1);
          return {cut: cut, wide: wide};""")
    finally:
        driver.quit()
    assert got["cut"] == [] and got["wide"] == [], got
