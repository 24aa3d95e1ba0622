"""Solvers of one family are told apart by colour (harness/report/style.py): over the
project's solver registry, every two members of a family are at least ``MIN_WITHIN`` apart
in CIE94 delta E (about 1 is a just noticeable difference), the families still apart."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest

from contactbench.harness.report.core import natural_key
from contactbench.harness.report.style import MAX_SERIES, SolverStyles, cielab, delta_e

#: Two solvers of one family, at the least (a panel draws up to ten of them side by side).
MIN_WITHIN = 8.0
#: Two solvers of different families, at the least.
MIN_ACROSS = 9.0


def test_cielab_and_delta_e_give_the_reference_values() -> None:
    """sRGB white, black and red in CIE L*a*b* (D65); CIE94 of a lightness step is that step."""
    assert np.allclose(cielab((1.0, 1.0, 1.0)), (100.0, 0.0, 0.0), atol=0.01)
    assert np.allclose(cielab((0.0, 0.0, 0.0)), (0.0, 0.0, 0.0), atol=0.01)
    assert np.allclose(cielab((1.0, 0.0, 0.0)), (53.24, 80.09, 67.20), atol=0.02)
    assert cielab([(1.0, 1.0, 1.0)] * 4).shape == (4, 3)
    red, blue = cielab((1.0, 0.0, 0.0)), cielab((0.0, 0.0, 1.0))
    assert float(delta_e(red, red)) == 0.0 and float(delta_e(red, blue)) == pytest.approx(float(delta_e(blue, red)))
    assert float(delta_e((50.0, 0.0, 0.0), (60.0, 0.0, 0.0))) == pytest.approx(10.0)
    assert 0 < float(delta_e(red, blue)) < float(np.linalg.norm(red - blue))  # chroma weighed down


def test_every_family_s_members_in_the_registry_are_told_apart() -> None:
    from contactbench.solvers.registry import all_solvers

    fams = {name: s.family for name, s in all_solvers().items() if s.family != "test"}  # not the tests' own
    fams.update({f"ext{i}": "external" for i in range(3)} | {f"mine{i}": "other" for i in range(3)})
    st = SolverStyles(fams, natural_key)
    lab = {s: cielab(st.color(s)) for s in fams}
    dist = {(a, b): float(delta_e(lab[a], lab[b])) for a, b in combinations(sorted(fams), 2)}
    within = {f: min((d, p) for p, d in dist.items() if st.family(p[0]) == st.family(p[1]) == f)
              for f in st.families if len(st.members(f)) > 1}
    assert max(len(st.members(f)) for f in within) >= MAX_SERIES  # a family that fills a panel
    assert all(d >= MIN_WITHIN for d, _ in within.values()), within
    across = min((d, p) for p, d in dist.items() if st.family(p[0]) != st.family(p[1]))
    assert across[0] >= MIN_ACROSS, across



def test_every_palette_colour_stands_out_on_white() -> None:
    """WCAG contrast against white at least ``MIN_CONTRAST`` (2:1) for every colour of every
    family's palette (a pale yellow at 1.3:1 and a pale blue could not be seen as lines)."""
    from contactbench.harness.report.style import FAMILY_HUES, MIN_CONTRAST, contrast_on_white, family_palette

    assert MIN_CONTRAST >= 2.0
    assert float(contrast_on_white((1.0, 1.0, 1.0))) == pytest.approx(1.0)
    assert float(contrast_on_white((0.0, 0.0, 0.0))) == pytest.approx(21.0)
    assert float(contrast_on_white((0xF4 / 255, 0xE0 / 255, 0x76 / 255))) < 1.5  # the pale yellow
    for family in (*FAMILY_HUES, "an-outside-family"):
        low = [c for c in family_palette(family) if float(contrast_on_white(c)) < MIN_CONTRAST]
        assert not low, (family, low)
