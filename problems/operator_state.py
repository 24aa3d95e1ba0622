"""What the operators, and the FFT machinery they hold, keep besides their defining arrays:
the declarations the seal of a solver's problem (``harness.judging.ProblemSeal``) reads.

An operator object holds more than the arrays that define H: counts of its products, work
buffers every product rewrites, the plan of its last product, caches built on first use
(the FFT operator's dense block, the kernel spectrum in float32 or transposed, the ducc0
work arrays, window spectra, entry floors) and, on a device, memory the host cannot read.
The seal reads everything an operator holds; a ``SealRule`` names the state of a class it
reads by another rule than "sealed by content".  What no rule names is sealed by content,
so a cache or buffer added to a class without naming it in its rule reads as a write into
the problem the first time a solve changes it (tests/harness/test_seal_private.py runs
every kind of product under a seal to hold the rules complete).

Each class declares its own rule beside its code, as the class attribute ``SEAL_RULE``
(``RULE_ATTRIBUTE``): ``seal_rule`` merges those its MRO declares, so a subclass is sealed
by its bases' rules and its own, and a class whose MRO declares none is sealed wholly by
content.  Nothing here names a class: the modules that declare rules import this one, which
imports none of them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Callable

#: rebuild(owner, key, current): the value a cache of ``owner`` holds when built afresh from
#: the sealed state -- ``key`` the entry of a dict cache (None for an attribute), ``current``
#: what the cache holds now (whose sizes a rebuild may follow: the buffers of each thread).
Rebuild = Callable[[Any, Any, Any], Any]
#: verify(owner, value): whether opaque state ``value`` of ``owner`` holds what the owner
#: itself puts there (``SealRule.opaque``).
Verify = Callable[[Any, Any], bool]

#: The class attribute a class declares its ``SealRule`` in (module doc).
RULE_ATTRIBUTE = "SEAL_RULE"


@dataclass(frozen=True)
class SealRule:
    """How the seal reads a class's state besides what it seals by content:

    * ``counters``: counts of products -- any count, but a plain ``int``;
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


def declared_rule(cls: type) -> SealRule | None:
    """The rule ``cls`` itself declares (``RULE_ATTRIBUTE`` in its own namespace, not one it
    inherits), None when it declares none; a declaration that is not a ``SealRule`` is a
    ``TypeError`` naming the class."""
    rule = vars(cls).get(RULE_ATTRIBUTE)
    if rule is not None and not isinstance(rule, SealRule):
        raise TypeError(f"{cls.__module__}.{cls.__qualname__}.{RULE_ATTRIBUTE} must be a SealRule, "
                        f"got {type(rule).__qualname__}")
    return rule


@lru_cache(maxsize=None)
def seal_rule(cls: type) -> SealRule:
    """The rules of ``cls``: those each class of its MRO declares, merged, a subclass's
    over its bases' (module doc); none declared: the empty rule (all sealed by content)."""
    rules = [rule for c in reversed(cls.__mro__) if (rule := declared_rule(c)) is not None]
    return SealRule(
        counters=frozenset().union(*(r.counters for r in rules)),
        work=frozenset().union(*(r.work for r in rules)),
        per_product={name: rebuild for r in rules for name, rebuild in r.per_product.items()},
        caches={name: rebuild for r in rules for name, rebuild in r.caches.items()},
        opaque={name: verify for r in rules for name, verify in r.opaque.items()},
    )
