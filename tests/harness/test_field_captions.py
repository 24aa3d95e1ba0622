"""A field figure's caption reads the stored gap: "g = 0" where the problem has no hardness
or every contact point is closed within the answer's tolerance; on a plastic field it gives
the share pressed below g = 0 (the elements at the hardness bound) and how far."""

from __future__ import annotations

import numpy as np

from contactbench.harness.report.sections.fields import contact_gap_text
from contactbench.harness.table.fields import ContactField


def field(gap_at_contact: float) -> ContactField:
    heights = np.linspace(0.0, 1e-6, 16).reshape(4, 4)
    contact = np.zeros((4, 4), bool)
    contact[0, :2] = True
    gap = np.where(contact, 0.0, 1e-7)
    gap[0, 0] = gap_at_contact
    return ContactField("plastic-sweep", "x", 1, 2, "pk", heights, np.where(contact, 1.0, 0.0), gap, contact, 4,
                        1e-6, 1e9, 0.0, 1.0, 1e-3, 0.125, 0.2, "m", False)


def test_an_elastic_field_has_its_contact_closed() -> None:
    assert contact_gap_text(field(-1e-20), bounded=True).endswith("have g = 0")


def test_a_plastic_field_says_how_many_contact_points_are_pressed_and_how_far() -> None:
    text = contact_gap_text(field(-5e-7), bounded=True)
    assert "50 % of them are pressed below it" in text and "-5.00e-07 m" in text and "hardness" in text


def test_without_a_hardness_no_contact_point_is_called_plastic() -> None:
    assert contact_gap_text(field(-1.5e-13), bounded=False).endswith("have g = 0")
    assert contact_gap_text(field(-5e-7), bounded=False).endswith("have g = 0")


def test_a_gap_within_the_answer_s_check_is_closed_and_one_beyond_it_is_pressed() -> None:
    assert contact_gap_text(field(-5e-13), bounded=True, check_tol=1e-6).endswith("have g = 0")
    assert "pressed below it" in contact_gap_text(field(-5e-12), bounded=True, check_tol=1e-9)
