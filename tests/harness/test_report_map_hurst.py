"""A measured map has no Hurst exponent (its rows' ``hurst`` is NaN): the CMR report puts it
in no H group.  Fig. 8, drawn against H, leaves such instances out and names them; a table
of measured maps only says that is why Fig. 8 is not drawn."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from contactbench.harness.report.sections import cmr_figures as rcf
from tests.harness.test_report_cmr import _section, fabricate_cmr


def measured(table: pd.DataFrame) -> pd.DataFrame:
    """The fabricated CMR table as if each instance were a measured map: no H, no seed, a file."""
    out = table.copy()
    out["hurst"], out["seed"], out["surface_source"] = np.nan, pd.NA, "m.npy"
    out["instance"] = "file-m.npy-" + out["instance"]
    return out


def test_a_table_of_measured_maps_says_they_have_no_hurst_exponent(tmp_path: Path) -> None:
    table, _ = fabricate_cmr(family="")
    out, section = _section(tmp_path, measured(table), rcf.cmr_section)
    assert "its instances are measured maps, which have none" in section and "`hurst` column" not in section
    assert not out.exists()


def test_measured_maps_beside_generated_surfaces_are_left_out_of_the_h_groups(tmp_path: Path) -> None:
    table, _ = fabricate_cmr(family="")
    maps = measured(table)
    _, section = _section(tmp_path, pd.concat([table, maps], ignore_index=True), rcf.cmr_section)
    names = sorted(set(maps["instance"]))
    left_out = f"Left out of Fig. 8: {len(names)} instance(s) with no Hurst exponent ({', '.join(names)})."
    assert left_out in section
    rest = section.replace(left_out, "")
    assert "file-m.npy-" not in rest and not re.search(r"\bnan\b", rest, re.I)  # in no H group, no H = nan
