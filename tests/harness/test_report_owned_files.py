"""A report writes over none but its own files (harness/report/owned_files.py): in a folder
never reported, a user's report.md, report.html or figure of a name the report writes is
refused with one line naming it (exit 2), and left byte for byte; a folder reported before
is reported again in place."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness.report import build
from contactbench.harness.report.core import ReportInputError
from contactbench.harness.report.figure_files import MANIFEST
from contactbench.harness.report.owned_files import write_own_page
from contactbench.harness.report.sections.claims import CLAIMS_TITLE, write_claims_md
from contactbench.harness.report.sections.population import POPULATION_TITLE, write_population_report
from contactbench.harness.report.sections.stress import STRESS_TITLE, write_stress_report
from tests.helpers import fabricate_table, run_cli, write_out

MINE = b"my own notes, not a report\n"


def hertz_out(tmp: Path) -> Path:
    """A results folder of the fabricated table's hertz rows, never reported."""
    df = fabricate_table()
    return write_out(tmp, df[df["scene"] == "hertz"])


def only_hertz_section(monkeypatch: pytest.MonkeyPatch) -> None:
    """The report renders the hertz section alone (one figure, analytic-hertz.png: fast)."""
    every = build.registered_sections
    monkeypatch.setattr(build, "registered_sections", lambda: {k: v for k, v in every().items() if k == "hertz"})


def pngs(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in (out / "figures").glob("*.png")} if (out / "figures").is_dir() else {}


@pytest.mark.parametrize("name", ["report.md", "report.html"])
def test_a_user_s_page_of_a_report_s_name_is_refused_and_left_as_it_is(
        tmp_path: Path, capsys: pytest.CaptureFixture, name: str) -> None:
    out = hertz_out(tmp_path)
    (out / name).write_bytes(MINE)
    rc, _, err = run_cli(["report", str(out)], capsys)
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(out / name) in lines[0] and "not written by a report" in lines[0], err
    assert (out / name).read_bytes() == MINE
    assert {p.name for p in out.iterdir()} == {"results.parquet", "meta.json", name}  # nothing written


def test_a_user_s_figure_of_a_report_s_name_is_refused_and_left_as_it_is(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The figure's name is known once rendered: the report is refused then, before report.md
    is written or any figure published, and its staging is discarded.  With the file moved
    away the report is written, and written again in place (its figures are its own); a
    user's figure of another name stays."""
    only_hertz_section(monkeypatch)
    out = hertz_out(tmp_path)
    (out / "figures").mkdir()
    (out / "figures" / "analytic-hertz.png").write_bytes(MINE)
    (out / "figures" / "mine.png").write_bytes(MINE)
    with pytest.raises(ReportInputError, match="analytic-hertz.png was not written by a report"):
        build.build_report(out, html=False)
    assert pngs(out) == {"analytic-hertz.png": MINE, "mine.png": MINE}
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["analytic-hertz.png", "mine.png"]  # no staging
    assert not (out / "report.md").exists()
    (out / "figures" / "analytic-hertz.png").rename(out / "moved.png")
    build.build_report(out, html=False)
    first = (out / "report.md").read_bytes(), pngs(out)
    assert first[1]["mine.png"] == MINE and first[1]["analytic-hertz.png"] != MINE
    build.build_report(out, html=False)
    assert ((out / "report.md").read_bytes(), pngs(out)) == first


def _report_md(links: list[str]) -> str:
    from contactbench.harness.report.owned_files import page_starts

    return page_starts()["report.md"].decode() + "x\n\n" + "".join(f"![Figure 1](figures/{n})\n" for n in links)


def test_a_figure_is_ours_when_the_record_lists_it_or_with_no_record_when_report_md_links_it(tmp_path: Path) -> None:
    from contactbench.harness.report.owned_files import foreign_files

    fig = tmp_path / "figures"
    fig.mkdir()
    for n in ("a.png", "b.png"):
        (fig / n).write_bytes(MINE)
    (tmp_path / "report.md").write_text(_report_md(["a.png"]))
    names = ["report.md", "figures/a.png", "figures/b.png", "figures/absent.png"]
    assert foreign_files(tmp_path, names) == [fig / "b.png"]  # no record: report.md's links
    (fig / MANIFEST).write_text('["b.png"]\n')
    assert foreign_files(tmp_path, names) == [fig / "a.png"]  # the record, once there, alone
    (fig / MANIFEST).write_text("not json")
    assert foreign_files(tmp_path, names) == [fig / "a.png", fig / "b.png"]  # an unreadable record: none ours
    (fig / MANIFEST).unlink()
    (tmp_path / "report.md").write_text("# my report\n\n![Figure 1](figures/a.png)\n")
    assert foreign_files(tmp_path, names) == [tmp_path / "report.md", fig / "a.png", fig / "b.png"]


def test_a_page_is_ours_when_it_begins_as_a_report_s_page_begins(tmp_path: Path) -> None:
    from contactbench.harness.report.owned_files import foreign_files, page_starts

    starts = page_starts()
    (tmp_path / "report.html").write_bytes(starts["report.html"] + b"suite</title>\n")
    (tmp_path / "report.md").write_bytes(starts["report.html"])  # the other page's start: not ours
    assert foreign_files(tmp_path, ["report.html", "report.md"]) == [tmp_path / "report.md"]
    (tmp_path / "report.md").unlink()
    (tmp_path / "report.md").symlink_to(tmp_path / "report.html")  # a link is the user's, whatever it points at
    assert foreign_files(tmp_path, ["report.md", "report.html"]) == [tmp_path / "report.md"]


def test_the_pages_a_report_wrote_begin_as_page_starts_says(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``page_starts`` and the writers agree: a report's own pages are recognised as its own."""
    from contactbench.harness.report.owned_files import foreign_files

    only_hertz_section(monkeypatch)
    out = hertz_out(tmp_path)
    build.build_report(out)
    assert foreign_files(out, ["report.md", "report.html", "figures/analytic-hertz.png"]) == []


@pytest.mark.parametrize("name, title", [("claims.md", CLAIMS_TITLE), ("population.md", POPULATION_TITLE),
                                         ("README.md", STRESS_TITLE)])
def test_a_writer_s_page_is_written_over_only_when_it_wrote_it(tmp_path: Path, name: str, title: str) -> None:
    """The report's other pages follow report.md's rule (owned_files.py ``write_own_page``):
    a user's file of the page's name, or a link, is refused in one line and left as it is;
    the page the writer made is written over."""
    mine = tmp_path / name
    mine.write_text("my own notes\n")
    with pytest.raises(ReportInputError, match=f"{name} was not written by a report") as refused:
        write_own_page(mine, title, "new\n")
    assert str(refused.value).count("\n") == 0 and mine.read_text() == "my own notes\n"
    link = tmp_path / "linked" / name
    link.parent.mkdir()
    link.symlink_to(mine)
    with pytest.raises(ReportInputError):
        write_own_page(link, title, "new\n")
    fresh = tmp_path / "fresh" / name
    fresh.parent.mkdir()
    assert write_own_page(fresh, title, "first\n").read_text() == f"# {title}\nfirst\n"
    assert write_own_page(fresh, title, "second\n").read_text() == f"# {title}\nsecond\n"


@pytest.mark.parametrize("name", ["claims.md", "population.md", "README.md"])
def test_the_claims_population_and_stress_writers_leave_a_user_s_page(tmp_path: Path, name: str) -> None:
    """claims.md, population.md and the stress battery's README.md are written by their
    writers only over a page of theirs: a user's file of that name stops the writer, in one
    line, before it reads or writes anything."""
    writer = {"claims.md": write_claims_md, "population.md": write_population_report,
              "README.md": write_stress_report}[name]
    (tmp_path / name).write_bytes(MINE)
    with pytest.raises(ReportInputError, match=f"{name} was not written by a report") as refused:
        writer(tmp_path)
    assert "\n" not in str(refused.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name] and (tmp_path / name).read_bytes() == MINE


@pytest.mark.parametrize("name", ["report.md", "report.html"])
def test_run_report_refuses_a_user_s_page_before_it_solves(
        tmp_path: Path, capsys: pytest.CaptureFixture, name: str) -> None:
    """``run --report`` into a folder holding a page of a report's name that no report wrote:
    one line naming it, exit 2, and no solve run (no table, no run record)."""
    out = tmp_path / "run"
    out.mkdir()
    (out / name).write_bytes(MINE)
    rc, _, err = run_cli(["run", "hertz", "--solvers", "nnls", "--out", str(out), "--report", "--no-progress"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and str(out / name) in lines[0] and "not written by a report" in lines[0], err
    assert {p.name for p in out.iterdir()} == {name} and (out / name).read_bytes() == MINE
