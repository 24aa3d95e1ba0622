"""A name in the table (a solver's, a scene's) is text in report.md and report.html,
never markup: a hostile name neither runs script on the page nor writes a tag."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness.report.browser import browser_missing, load_page, open_driver
from contactbench.harness.report.build import build_report
from contactbench.harness.report.markdown_text import md_code, md_escape
from tests.helpers import fabricate_table, write_out

HOSTILE = "<img src=x onerror=\"document.title='PWNED'\">"


def hostile_report(tmp: Path) -> Path:
    """The hertz rows of the fabricated table, nnls renamed ``HOSTILE``, reported."""
    df = fabricate_table()
    df = df[df["scene"] == "hertz"].copy()
    df.loc[df["solver"] == "nnls", "solver"] = HOSTILE
    out = write_out(tmp, df)
    build_report(out)
    return out


def test_a_tag_in_a_markdown_cell_is_text() -> None:
    assert md_escape(HOSTILE).startswith("&lt;img") and md_escape("n <= 10 | a") == "n <= 10 \\| a"
    assert md_escape("</script><!-- x") == "&lt;/script>&lt;!-- x"
    assert md_code("pk") == "`pk`" and md_code("a`b") == "``a`b``" and md_code("`x") == "`` `x ``"


def test_a_backtick_in_a_name_cannot_end_its_code_span(tmp_path: Path) -> None:
    """A solver name with a backtick is still one code span in report.md's prose (it ended
    the span, and the rest of the name was read as a live tag)."""
    df = fabricate_table()
    df = df[df["scene"] == "counterexample"].copy()
    name = "x` <img src=x onerror=alert(1)> `y"
    df.loc[df["solver"] == df["solver"].iloc[0], "solver"] = name
    out = write_out(tmp_path, df)
    build_report(out, html=False)
    md = (out / "report.md").read_text()
    assert "``x` <img src=x onerror=alert(1)> `y``" in md
    assert all(line.count("``x`") == line.count("`y``") for line in md.splitlines())


def test_a_hostile_solver_name_is_text_on_the_page_and_in_report_md(tmp_path: Path) -> None:
    """The page's SGM table, scene headings and figure captions set names as text (the
    name's script ran when the page opened: the title read PWNED); report.md writes no tag."""
    out = hostile_report(tmp_path)
    md = (out / "report.md").read_text()
    assert "<img" not in md and "&lt;img" in md
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    driver = open_driver()
    try:
        load_page(driver, out / "report.html")
        assert driver.title != "PWNED"
        assert driver.execute_script("return document.querySelectorAll('img[onerror]').length;") == 0
        cells = driver.execute_script("return [...document.querySelectorAll('table.sgm td')].map(td => td.textContent);")
        assert HOSTILE in cells
    finally:
        driver.quit()
