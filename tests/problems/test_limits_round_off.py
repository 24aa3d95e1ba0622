"""Limits read to round-off: a bcc layer typed as exactly ``BCC_MIN_THICKNESS`` spacings is
taken; the load's share of bounds near the largest float is read without overflow; a single
element's load at its bound is not a saturated many-element problem for cm-pk-ccg; an
increasing list refused names its values to every digit."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from contactbench.problems.constraints import make_constraints
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.layers import BCC_MIN_THICKNESS, Layer
from contactbench.solvers.base import ProblemTraits
from contactbench.solvers.registry import get_solver


@pytest.mark.parametrize("L", [1e-4, 7e-5, 3e-5, 1e-4 / 3])
@pytest.mark.parametrize("N", [64, 100, 128, 255, 512])
def test_a_bcc_layer_of_exactly_the_least_thickness_typed_as_a_decimal_is_taken(L: float, N: int) -> None:
    d = L / N
    T = float(f"{BCC_MIN_THICKNESS * d:.15g}")  # as a user types it
    Layer(T).check_kernel("bcc", False, (d, d))
    with pytest.raises(ProblemInputError, match="too stiff"):
        Layer(T * (1 - 1e-6)).check_kernel("bcc", False, (d, d))


def test_the_share_of_bounds_near_the_largest_float_is_read_without_overflow() -> None:
    c = make_constraints(2, upper=np.array([1e308, 1e308]), load=1e308)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c.check(2)
        assert c.capacity_share == pytest.approx(0.5)


def test_cm_pk_ccg_takes_one_element_at_its_bound() -> None:
    traits = replace(ProblemTraits(n=1, operator="fft", kernel="bcc", surface_side=1), load_control=True, bounded=True,
                     capacity_share=1.0)
    assert get_solver("cm-pk-ccg").skip(traits) is None
    assert "all elements but one" in (get_solver("cm-pk-ccg").skip(replace(traits, n=4)) or "")
