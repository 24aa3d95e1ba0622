"""The flag of the plastic share: ``plastic_uncertain``.

``ContactInstance.plastic_fraction`` counts an element in contact as plastic when it sits at
its bound, u_i - p_i <= floor with u_i finite (``ContactInstance.plastic_mask``; the floor is
``ContactInstance.contact_floor``, tol x p_s, p_s the problem's force scale).  Like the contact
count (``ContactInstance.contact_uncertain``), that reading is not pinned by a KKT residual: an
answer the judge accepts at ``tol`` may leave an element that is plastic in the exact answer a
little below its bound (its bound multiplier times its slack, scaled, is at most tol, so a
slack of order sqrt(tol) x p_s passes).  ``plastic_uncertain`` is the share of the elements in
contact whose plastic state the tolerance leaves open -- the same denominator as
``plastic_fraction`` -- so that |plastic share - exact plastic share| is read against it.
"""

from __future__ import annotations

import math

import numpy as np

from .instances import CONTACT_BAND, ContactInstance


def plastic_open(inst: ContactInstance, p: np.ndarray, tol: float) -> np.ndarray:
    """Elements whose plastic state ``tol`` leaves open (a bool per element; none without a
    finite bound): those with a finite bound u_i whose slack s_i = u_i - p_i

    * lies within a factor ``CONTACT_BAND`` (a decade) of the plastic floor f
      (``plastic_mask``'s, the ``contact_floor`` tol x p_s): f / CONTACT_BAND < s_i <=
      f x CONTACT_BAND -- the band of ``contact_uncertain``, on the slack, or
    * is counted elastic (s_i > f) while s_i <= sqrt(tol) x p_s: an accepted answer's bound
      multiplier times slack is at most tol (scaled), so such an element may be plastic in
      the exact answer."""
    q = np.asarray(p, dtype=np.float64)
    c = inst.qp.constraints
    if not c.bounded:
        return np.zeros(q.shape, dtype=bool)
    u = c.upper_or_inf(inst.n)
    floor = inst.contact_floor(tol)
    reach = math.sqrt(float(tol)) * inst.force_scale()
    plastic = inst.plastic_mask(q, tol)
    with np.errstate(invalid="ignore"):
        slack = u - q
        near = np.isfinite(u) & (slack > floor / CONTACT_BAND) & (slack <= floor * CONTACT_BAND)
        close_elastic = np.isfinite(u) & ~plastic & (slack <= reach)
    return near | close_elastic


def plastic_uncertain(inst: ContactInstance, p: np.ndarray, tol: float) -> float:
    """The flag of ``plastic_fraction``: the elements in contact (``contact_mask``) whose
    plastic state ``tol`` leaves open (``plastic_open``), over the elements in contact (the
    denominator of ``plastic_fraction``); 0 when none touches, NaN without a bound (a
    problem without a hardness, as the table's ``plastic_fraction``).  A flag larger than
    the accuracy wanted means the plastic share is not to be trusted to it."""
    if not inst.qp.constraints.bounded:
        return math.nan
    touching = inst.contact_mask(p, tol)
    k = int(np.count_nonzero(touching))
    return float(np.count_nonzero(plastic_open(inst, p, tol) & touching)) / k if k else 0.0


__all__ = ["plastic_open", "plastic_uncertain"]
