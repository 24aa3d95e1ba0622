"""The scenes of paper Example 1's two variants (``problems.example1_variants``): the
``counterexample`` scene with its ``spacing`` or ``matrix`` set (``core.Counterexample``
builds them), each under its own name so that its rows never pool with Example 1's (the
counterexample section, its page chart and the ledger's ``ex1-greedy-fails`` read every row
of scene ``counterexample`` per n).  n = 25 and 100 over seeds 0-99, the dense H."""

from __future__ import annotations

from . import register_scene
from .base import SceneConfig
from .core import Counterexample

#: The sizes of the variants (n = N^2 trial elements).
VARIANT_SIZES: tuple[int, ...] = (25, 100)


@register_scene
class Counterexample2Delta(Counterexample):
    """Example 1 with its trial elements 2 delta apart (tex 647-651): every other element of
    a (2N - 1) x (2N - 1) mesh, Q from Eq. (green2) between them (``spaced_counterexample``)."""

    name = "counterexample-2delta"
    description = ("Example 1 with its N x N trial elements 2 delta apart (tex 647-651): n = 25, 100, "
                   "ubar ~ U(0,1), seeds 0-99")
    defaults = SceneConfig(seeds=tuple(range(100)), operator="dense", extra={"sizes": VARIANT_SIZES, "spacing": 2})


@register_scene
class RandomPositiveH(Counterexample):
    """ubar ~ U(0, 1) and a random SPD Q with positive entries (tex 601-604;
    ``random_positive``: Q = B B' / n, B ~ U(0, 1)), the dense H only."""

    name = "random-positive-h"
    description = ("random ubar ~ U(0,1) and random SPD Q = B B'/n with positive entries (tex 601-604): "
                   "n = 25, 100, seeds 0-99, dense only")
    defaults = SceneConfig(seeds=tuple(range(100)), operator="dense",
                           extra={"sizes": VARIANT_SIZES, "matrix": "random-positive"})
    options = frozenset({"size", "seeds"})  # a random matrix has no FFT form: the dense H
