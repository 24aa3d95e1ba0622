"""What the operators, and the FFT machinery they hold, keep besides their defining arrays:
the declarations the seal of a solver's problem (``harness.judging.ProblemSeal``) reads.

An operator object holds more than the arrays that define H: counts of its products, work
buffers every product rewrites, the plan of its last product, caches built on first use
(the FFT operator's dense block, the kernel spectrum in float32 or transposed, the ducc0
work arrays, window spectra, entry floors) and, on a device, memory the host cannot read.
The seal reads everything an operator holds; ``SealRule`` names, per class, the state it
reads by another rule than "sealed by content".  What no rule names is sealed by content,
so a cache or buffer added to a class without a rule here reads as a write into the problem
the first time a solve changes it (tests/harness/test_seal_private.py runs every kind of
product under a seal to hold this list complete).

The rules are keyed by class name (``type.__qualname__``, looked up along the MRO): the
device classes (problems/operators_gpu.py) import this module's classes, not the reverse.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Callable

import numpy as np

from .fft_transform import KernelTransform

#: rebuild(owner, key, current): the value a cache of ``owner`` holds when built afresh from
#: the sealed state -- ``key`` the entry of a dict cache (None for an attribute), ``current``
#: what the cache holds now (whose sizes a rebuild may follow: the buffers of each thread).
Rebuild = Callable[[Any, Any, Any], Any]
#: verify(owner, value): whether opaque state ``value`` of ``owner`` holds what the owner
#: itself puts there (``SealRule.opaque``).
Verify = Callable[[Any, Any], bool]


@dataclass(frozen=True)
class SealRule:
    """How the seal reads a class's state besides what it seals by content:

    * ``counters``: counts of products -- not state, not read;
    * ``work``: work buffers that every product writes before it reads them (paths relative
      to the object, ``[*]`` for any entry): sealed by their layout (shape, dtype, strides,
      the memory they view), never by what they hold;
    * ``per_product``: the plan of the last product, which any product may replace, each
      with its ``Rebuild`` (the plan of the same key, made afresh): left out of the cache
      it lies in; a solve's plan is kept where it is its rebuild (so a timed solve reuses
      its warm-up's), else put back to None (the next product makes its own);
    * ``caches``: state built on first use from the sealed state, each with its ``Rebuild``
      (a dict cache: per entry): a cache a solve built or changed must equal its rebuild,
      else the solve wrote into the problem; one it dropped is built again on first use;
    * ``opaque``: state the seal cannot read in place (device memory), each with its
      ``Verify``: what a solve left there is kept where it holds what the operator puts
      there (a copy back to the host, compared), so a timed solve reuses its warm-up's
      upload; anything else is put back as sealed.
    """

    counters: frozenset[str] = frozenset()
    work: frozenset[str] = frozenset()
    per_product: dict[str, Rebuild] = field(default_factory=dict)
    caches: dict[str, Rebuild] = field(default_factory=dict)
    opaque: dict[str, Verify] = field(default_factory=dict)


def pristine_transform(transform: KernelTransform) -> KernelTransform:
    """A twin of ``transform`` sharing its table and spectrum, with none of its caches
    (its own pickling state: ``KernelTransform.__getstate__``)."""
    twin = copy.copy(transform)
    twin._floor = None
    return twin


def _fresh_work(transform: KernelTransform, name: str, current: Any) -> Any:
    """The ducc0 work arrays of precision ``name`` made afresh, with as many per-thread
    buffers as ``current`` holds (made on first use by as many threads)."""
    work = pristine_transform(transform)._ducc_work(np.dtype(name))
    for attr, make in (("_buffers", work.buffers), ("_row_buffers", work.row_buffers)):
        held = getattr(current, attr, None)
        make(len(held) if type(held) is list else 0)
    if isinstance(getattr(current, "_field", None), np.ndarray):
        work.field()
    return work


#: The rules, by class name (module doc).
SEAL_RULES: dict[str, SealRule] = {
    "ContactOperator": SealRule(counters=frozenset({"matvec_count"})),
    "FFTOperator": SealRule(caches={
        "_dense": lambda op, key, current: op._dense_block(),
        "_window_spectra": lambda op, shape, current: op._fresh_window_spectrum(shape),
    }),
    "DenseOperator": SealRule(caches={"_floor": lambda op, key, current: op._fresh_floor()}),
    "KernelTransform": SealRule(counters=frozenset({"fft_count"}), caches={
        "_khat32": lambda t, key, current: pristine_transform(t).spectrum(np.float32),
        "_transposed": lambda t, name, current: pristine_transform(t).transposed_spectrum(np.dtype(name)),
        "_floor": lambda t, key, current: pristine_transform(t).floor,
        "_works": _fresh_work,
    }),
    "_DuccWork": SealRule(work=frozenset({"whole", "rows", "_buffers[*]", "_row_buffers[*][1]", "_field"}),
                          per_product={"_last": lambda work, key, current: work.fresh_plan(current.key)}),
    "ArrayKernelTransform": SealRule(opaque={"_device": lambda t, state: t.device_state_intact(state)}),
}


@lru_cache(maxsize=None)
def seal_rule(cls: type) -> SealRule:
    """The rules of ``cls``: those of each class of its MRO, merged (module doc)."""
    rules = [SEAL_RULES[c.__qualname__] for c in reversed(cls.__mro__) if c.__qualname__ in SEAL_RULES]
    return SealRule(
        counters=frozenset().union(*(r.counters for r in rules)),
        work=frozenset().union(*(r.work for r in rules)),
        per_product={name: rebuild for r in rules for name, rebuild in r.per_product.items()},
        caches={name: rebuild for r in rules for name, rebuild in r.caches.items()},
        opaque={name: verify for r in rules for name, verify in r.opaque.items()},
    )
