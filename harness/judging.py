"""The judge: the one place that turns an answer into a verdict (docs/verdicts.md).

``run`` (the worker), ``validate``, ``solve_sequence``, pytest-benchmark and the
benchmark scripts all call ``judge``.  A verdict carries two readings of one answer:

* ``status``  -- the table's reading: "solved" when the scaled KKT error
  (``contactbench.problems.kkt.kkt_check``, recomputed from the harness's own H and
  ubar, never the solver's w or figure) is at most the profile's ``check_tol``;
  "inaccurate" when it is not; "failed" when the answer is no answer (``read_answer``:
  not a length-n vector of finite real numbers) or the solver wrote into the problem it
  was handed (``ProblemSeal``);
* ``reading`` -- the conformance reading, which also weighs the solver's own claim:
  "pass" (solved, and p within ``p_tol`` of the reference when one is given: relatively,
  or absolutely on the force scale, ``near_reference``),
  "wrong" (not that, while the solver claimed convergence; and any answer of a solver
  that wrote into its problem), or "unconverged" (not that, and the solver said so).

Every figure is NaN- and overflow-safe (``problems.kkt``): nothing non-finite can make a
verdict better.  The scales come from the problem, never from the candidate.  Under load
control the figures are read at the approach the judge fits and at the one the solver
reports, the smaller kept (``answer_report``: each is a certificate).

The judge computes with the operator the solver was handed, checked by ``ProblemSeal``:
everything the operator holds is sealed -- private caches by what the operator builds from
the sealed state, work buffers by their layout (their content is written by every product
before it is read), by the rules of ``contactbench.problems.operator_state`` -- and ``mend``
drops a cache that is not its rebuild, so the judge builds its own.  Judging on a copy made
before the solve, or on a rebuild, would be as sound but costs what the operator holds for
every solve (hundreds of MB at 4096^2: the kernel table, its spectrum, the transposed copy,
the work arrays); the seal reads them, and rebuilds a cache once when a solve built it.
"""

from __future__ import annotations

import hashlib
import math
import re
import types
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any, Sequence

import numpy as np

from contactbench.problems.errors import ProblemInputError, check_positive, printable_excerpt
from contactbench.problems.instances import CONTACT_TOL, ContactInstance
from contactbench.problems.kkt import KKTReport, kkt_check, relative_error, relative_load_error
from contactbench.problems.operator_state import Rebuild, SealRule, Verify, seal_rule
from contactbench.problems.plastic_share import plastic_uncertain
from contactbench.solvers._answers import is_real

from .table.schema import VERDICTS as READINGS  # the table contract names the readings

__all__ = ["READINGS", "ProblemSeal", "UnreadAnswer", "Verdict", "answer_figures", "judge", "portable_answer",
           "read_answer", "shown_apart"]


@dataclass
class Verdict:
    """The judge's verdict on one answer (module doc).  ``usable``: the answer was a
    length-n vector of finite real numbers and the problem was left as handed.
    ``kinds`` names each of ``problems``, in order: "answer" (no answer), "tampered",
    "dtype" (p not float64), "kkt" (above check_tol), "reference" (beyond p_tol)."""

    status: str  # "solved" | "inaccurate" | "failed"
    reading: str  # "pass" | "wrong" | "unconverged"
    claimed: bool
    kkt: KKTReport | None
    figures: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    tampered: bool = False  # the solver wrote into the problem it was handed
    kinds: list[str] = field(default_factory=list)

    @property
    def kkt_error(self) -> float:
        return math.inf if self.kkt is None else float(self.kkt.kkt_error)

    @property
    def usable(self) -> bool:
        return self.status != "failed"

    @property
    def correct_claim(self) -> bool:
        return self.claimed == (self.status == "solved")

    def message(self) -> str:
        text = "; ".join(self.problems)
        if self.reading == "wrong" and self.claimed:
            text += " -- while claiming convergence"
        elif self.reading == "pass" and not self.claimed:
            text = "correct, though the solver did not claim convergence"
        return text


# ---------------------------------------------------------------------------
# The problem a solver was handed: sealed before the solve, checked after
# ---------------------------------------------------------------------------

#: What the seal reads as a value (by ``repr``), not as an object to look into.
_SCALARS = (int, float, complex, str, bytes, bool, type(None), np.generic, np.dtype)


@dataclass(frozen=True)
class _Context:
    """Where the reader stands: the rules of the nearest object above (``seal_rule``), the
    path from that object (for its work patterns), and the declared slot it is inside."""

    rule: SealRule | None = None
    rel: str = ""
    cache: str = ""  # the outermost cache slot (``SealRule.caches``) above, "" none
    per_product: str = ""  # the per-product attribute above, "" none

    def into(self, step: str) -> _Context:
        return replace(self, rel=self.rel + step)


@dataclass(frozen=True)
class _Entry:
    """One piece of state as sealed: its fingerprint and the slot it lies in."""

    fingerprint: tuple[Any, ...]
    cache: str = ""
    per_product: str = ""
    opaque: bool = False


@dataclass
class _Slot:
    """A declared place state lives in (``SealRule``): ``holder[key]`` for an entry of a
    dict cache, else attribute ``key`` of ``holder``; a cache's ``rebuild`` is called as
    rebuild(``owner``, ``entry``, current value)."""

    holder: Any
    key: Any
    context: _Context
    rebuild: Rebuild | None = None
    owner: Any = None
    entry: Any = None
    verify: Verify | None = None

    @property
    def value(self) -> Any:
        if isinstance(self.holder, dict):
            return self.holder.get(self.key)
        return getattr(self.holder, self.key, None)

    def put(self, value: Any) -> None:
        """Put ``value`` back in the slot; None empties an entry of a dict cache."""
        if isinstance(self.holder, dict):
            if value is None:
                self.holder.pop(self.key, None)
            else:
                self.holder[self.key] = value
        else:
            setattr(self.holder, self.key, value)


@lru_cache(maxsize=None)
def _pattern(work: str) -> re.Pattern[str]:
    return re.compile(re.escape(work).replace(re.escape("[*]"), r"\[[^\]]+\]") + r"\Z")


def _is_work(context: _Context) -> bool:
    rule = context.rule
    return rule is not None and any(_pattern(w).match(context.rel) for w in rule.work)


def _opaque_value(value: Any) -> bool:
    """What the seal names by identity: classes, modules, anything callable, and objects
    with no attributes to read (a lock)."""
    return isinstance(value, (type, types.ModuleType)) or callable(value) or not hasattr(value, "__dict__")


class _Reader:
    """Reads the state of a problem: ``entries`` (path -> ``_Entry``), the declared
    ``slots`` (path -> ``_Slot``) and the ``parts`` (every object read, with its path)."""

    def __init__(self) -> None:
        self.entries: dict[str, _Entry] = {}
        self.slots: dict[str, _Slot] = {}
        self.parts: list[tuple[str, Any]] = []
        self._arrays: list[tuple[str, np.ndarray, _Context, bool]] = []
        self._first_path: dict[int, str] = {}
        self._digests: dict[int, str] = {}
        self._stack: set[int] = set()
        self._objects: dict[int, str] = {}  # id -> the path each object was read under

    def add(self, path: str, fingerprint: tuple[Any, ...], context: _Context, opaque: bool = False) -> None:
        self.entries[path] = _Entry(fingerprint, context.cache, context.per_product, opaque)

    def read(self, value: Any, path: str, context: _Context) -> None:
        if isinstance(value, np.ndarray):
            self._first_path.setdefault(id(value), path)
            self._arrays.append((path, value, context, _is_work(context)))
        elif isinstance(value, _SCALARS):
            self.add(path, ("value", type(value).__qualname__, repr(value)), context)
        elif type(value) in (list, tuple, dict) or isinstance(value, (list, tuple, dict)):
            self.add(path, (type(value).__module__, type(value).__qualname__, id(type(value))), context)
            items = value.items() if isinstance(value, dict) else enumerate(value)
            for key, item in sorted(items, key=lambda kv: repr(kv[0])):
                step = f"[{key!r}]"
                self.read(item, path + step, context.into(step))
        elif _opaque_value(value) or id(value) in self._stack:
            self.add(path, ("identity", type(value).__qualname__, id(value)), context)
        else:
            self.read_object(value, path, context)

    def read_object(self, obj: Any, path: str, context: _Context) -> None:
        """An object's state, read once: where it is met again (an operator's transform
        that another step's operator shares) it is named by the path it was read under."""
        first = self._objects.setdefault(id(obj), path)
        if first != path:
            self.add(path, ("same as", first), context)
            return
        self.add(path, ("object", type(obj).__module__, type(obj).__qualname__, id(type(obj))), context)
        self.parts.append((path, obj))
        self._stack.add(id(obj))
        rule = seal_rule(type(obj))
        for name, value in sorted(vars(obj).items(), key=lambda kv: kv[0]):
            where, inner = f"{path}.{name}", replace(context, rule=rule, rel=name)
            if name in rule.counters:  # any count, but a plain int: not a value that acts when counted
                self.add(where, ("counter", type(value) is int), inner)
                continue
            if name in rule.opaque:
                self.slots[where] = _Slot(obj, name, inner, owner=obj, verify=rule.opaque[name])
                self.add(where, ("identity", type(value).__qualname__, id(value)), inner, opaque=True)
            elif name in rule.caches and not context.cache:
                self.read_cache(obj, name, value, where, inner, rule.caches[name])
            else:
                if name in rule.per_product and not context.per_product:
                    inner = replace(inner, per_product=where)
                    self.slots[where] = _Slot(obj, name, inner, rule.per_product[name], obj, None)
                self.read(value, where, inner)
        self._stack.discard(id(obj))

    def read_cache(self, obj: Any, name: str, value: Any, where: str, context: _Context, rebuild: Rebuild) -> None:
        """A cache (``SealRule.caches``): an attribute, or each entry of a dict."""
        if not isinstance(value, dict):
            self.slots[where] = _Slot(obj, name, context, rebuild, obj, None)
            self.read(value, where, replace(context, cache=where))
            return
        self.add(where, (type(value).__module__, type(value).__qualname__, id(type(value))), context)
        for key, item in sorted(value.items(), key=lambda kv: repr(kv[0])):
            step = f"[{key!r}]"
            inner = replace(context.into(step), cache=where + step)
            self.slots[where + step] = _Slot(value, key, inner, rebuild, obj, key)
            self.read(item, where + step, inner)

    def finish(self) -> _Reader:
        """The arrays' fingerprints: a work buffer's layout, any other's content too."""
        for path, arr, context, work in self._arrays:
            layout = (arr.dtype.str, arr.shape, arr.strides, self._memory_of(arr))
            if work:
                self.add(path, ("work", *layout), context)
            else:
                self.add(path, ("array", *layout, self._digest(arr)), context)
        return self

    def _memory_of(self, arr: np.ndarray) -> str:
        """Whose memory ``arr`` views: its own, an array read here (by its path, at an
        offset), or memory from outside the problem."""
        root = arr
        while isinstance(root.base, np.ndarray):
            root = root.base
        if root is arr and arr.base is None:
            return "own"
        offset = arr.__array_interface__["data"][0] - root.__array_interface__["data"][0]
        path = self._first_path.get(id(root))
        return f"{path} at {offset}" if path is not None and root.base is None else "outside"

    def _digest(self, arr: np.ndarray) -> str:
        if id(arr) not in self._digests:
            self._digests[id(arr)] = _digest(arr)
        return self._digests[id(arr)]


def _read(qp: Any, held: tuple[Any, ...] = ()) -> _Reader:
    """The state of the problem handed to a solver -- ubar, its constraints (a load, the
    upper bounds of a hardness), everything the operator holds (``_Reader``) and its
    geometry (the unknowns' grid indices, the far field, the surface with its heights and
    coarse levels, from which the steps after are built) -- and of the problems ``held``
    beside it in the process (the judge's own, named ``held[i]``; an operator, constraints
    or a surface they share with ``qp`` are read once, under ``qp``'s name).  A held object
    that is no problem (no ``ubar``: the load sequence the later steps are built from) is
    read whole, with what its functions' closures hold (``_read_recipe``)."""
    reader = _Reader()
    for prefix, each in (("", qp), *((f"held[{i}].", q) for i, q in enumerate(held))):
        if not hasattr(each, "ubar"):
            _read_recipe(reader, each, prefix.rstrip("."))
            continue
        reader.read(np.asarray(each.ubar), f"{prefix}ubar", _Context())
        for name in ("constraints", "H", "geometry"):
            part = getattr(each, name, None)
            if part is not None:
                reader.read_object(part, f"{prefix}{name}", _Context())
    return reader.finish()


def _read_recipe(reader: _Reader, recipe: Any, path: str) -> None:
    """``recipe`` (a ``LoadSequence``) read whole, and the values its functions close over
    (a step factory's far-field displacements, loads and instance builder), each under
    ``<path>.<function>.<name>``: the seal names a function by its identity only, and a
    solver reaching them (``gc``) would change every step built after its solve."""
    reader.read_object(recipe, path, _Context())
    for name, fn in sorted(vars(recipe).items(), key=lambda kv: kv[0]):
        cells = getattr(fn, "__closure__", None) or ()
        for var, cell in zip(getattr(getattr(fn, "__code__", None), "co_freevars", ()), cells):
            try:
                value = cell.cell_contents
            except ValueError:  # a cell not yet filled
                continue
            if not _opaque_value(value):
                reader.read(value, f"{path}.{name}.{var}", _Context())


def _read_slot(value: Any, slot: _Slot, path: str) -> dict[str, _Entry]:
    """The entries of ``value`` read in place of what ``slot`` holds, at ``path``."""
    reader = _Reader()
    reader.read(value, path, slot.context)
    return reader.finish().entries


def _digest(arr: np.ndarray) -> str:
    h = hashlib.sha1(usedforsecurity=False)  # a fingerprint, not a defence against crafted collisions
    h.update(f"{arr.dtype.str}{arr.shape}".encode())
    h.update(memoryview(np.ascontiguousarray(arr)).cast("B"))
    return h.hexdigest()


def _methods(parts: list[tuple[str, Any]]) -> tuple[tuple[type, str, Any], ...]:
    """(class, name, attribute) of every method and descriptor the classes of the objects
    the operator holds define (their MROs, ``object`` aside): what a product runs."""
    classes = dict.fromkeys(c for _, part in parts for c in type(part).__mro__ if c is not object)
    return tuple((c, name, value) for c in classes for name, value in vars(c).items()
                 if callable(value) or isinstance(value, (staticmethod, classmethod, property)))


def _shadowing(parts: list[tuple[str, Any]]) -> tuple[tuple[Any, str, str, Any], ...]:
    """(object, attribute, seal name, value) of each attribute set on an object the
    operator holds that hides a method of its class (``H.matvec = ...``)."""
    return tuple((part, name, f"{where}.{name}", value) for where, part in parts
                 for name, value in vars(part).items() if callable(getattr(type(part), name, None)))


def _under(path: str, slot: str) -> bool:
    return path == slot or path.startswith(slot + ".") or path.startswith(slot + "[")


@dataclass
class _Findings:
    """What a check found: the paths written (``changed``), the cache slots whose state
    is not their rebuild (``bad_caches``), and the slots to put back (per-product state
    a solve replaced that is not its rebuild, opaque state that fails its check, which
    ``changed`` names too)."""

    reader: _Reader
    changed: list[str]
    bad_caches: list[str]
    per_product: list[str]
    opaque: list[str]


@dataclass(frozen=True, eq=False)  # (compared by identity: it holds the objects it put aside)
class ProblemSeal:
    """A fingerprint of the problem handed to a solver, taken before the solve: ubar, its
    constraints and geometry (``_read``), and everything the operator holds -- its defining
    arrays, its private arrays and those of
    the objects it holds, read by the rules of ``contactbench.problems.operator_state``
    (work buffers by their layout, caches held to their rebuild, counters by being plain ints) --
    and the methods its products run (``_methods``).  ``broken(qp)`` after the solve says
    what the solver changed ("" when nothing): an array written into (private ones
    included), a cache that is not what the operator builds, device state that is not what
    the operator put there (``SealRule.opaque``'s check, run at every check), a method of the operator's
    classes replaced, or one hidden by an attribute of the object (``_shadowing``).
    ``mend(qp)`` puts back what can be: the methods, the caches a solve built or changed
    that are not their rebuild (dropped: the judge builds its own), the plans of the last
    product that are not theirs (a solve's own plan is kept, for its timed solve after its
    warm-up) and the device state that fails its check (dropped); so the judge and the solves after it in the same process
    compute with the problem as sealed -- its defining arrays aside, which a write
    leaves as the solver left them (the harness then drops that problem)."""

    state: dict[str, _Entry]
    methods: tuple[tuple[type, str, Any], ...] = ()
    hiding: tuple[tuple[str, Any], ...] = ()  # (seal name, value): what hid a method when sealed
    held: tuple[Any, ...] = ()  # the problems sealed beside the one handed to the solver (``of``)
    _found: dict[int, _Findings] = field(default_factory=dict, compare=False, repr=False)

    @classmethod
    def of(cls, qp: Any, held: Sequence[Any] = ()) -> ProblemSeal:
        """The seal of ``qp`` and of the problems ``held`` beside it in the process (the
        judge's copies, other steps': a solver can reach any object of its process)."""
        others = tuple(q for q in held if q is not qp)
        reader = _read(qp, others)
        hiding = tuple((where, value) for _, _, where, value in _shadowing(reader.parts))
        return cls(reader.entries, _methods(reader.parts), hiding, others)

    def _new_hiding(self, parts: list[tuple[str, Any]]) -> list[tuple[Any, str, str, Any]]:
        """``_shadowing``'s entries that were not there, as they are, when sealed."""
        sealed = dict(self.hiding)
        return [(part, name, where, value) for part, name, where, value in _shadowing(parts)
                if where not in sealed or sealed[where] is not value]

    def _check(self, qp: Any) -> _Findings:
        reader = _read(qp, self.held)
        now, before = reader.entries, self.state
        changed, caches, per_product = [], set(), []
        for path in [*before, *(p for p in now if p not in before)]:
            old, new = before.get(path), now.get(path)
            if old is not None and new is not None and old.fingerprint == new.fingerprint:
                continue
            entry = new or old
            assert entry is not None
            if entry.per_product or (old is not None and old.per_product):
                per_product.append(entry.per_product or old.per_product)  # type: ignore[union-attr]
            elif entry.opaque:
                continue  # (checked in full below, replaced or not)
            elif entry.cache or (old is not None and old.cache):
                caches.add(entry.cache or old.cache)  # type: ignore[union-attr]
            else:
                changed.append(path)
        bad = [slot for slot in sorted(caches) if not self._rebuilt(slot, reader)]
        stale = [slot for slot in sorted(set(per_product)) if not self._rebuilt(slot, reader, within=True)]
        foreign = [path for path, slot in reader.slots.items() if slot.verify is not None and not self._intact(path, reader)]
        findings = _Findings(reader, changed + foreign, bad, stale, foreign)
        self._found.clear()
        self._found[id(qp)] = findings
        return findings

    @staticmethod
    def _intact(path: str, reader: _Reader) -> bool:
        """Whether the opaque slot ``path`` holds nothing or what its owner puts there
        (``SealRule.opaque``'s check)."""
        slot = reader.slots.get(path)
        if slot is None or slot.value is None:
            return True
        try:
            return slot.verify is not None and bool(slot.verify(slot.owner, slot.value))
        except Exception:  # a state its check cannot even read is not the operator's
            return False

    @staticmethod
    def _rebuilt(path: str, reader: _Reader, within: bool = False) -> bool:
        """Whether the cache slot ``path`` holds what the operator builds there (or nothing:
        a dropped cache is built again on use); the plans of the last product inside it
        left out, unless ``within`` (``path`` is such a plan)."""
        slot = reader.slots.get(path)
        if slot is None or slot.value is None or slot.rebuild is None:
            return slot is None or slot.value is None
        try:
            fresh = slot.rebuild(slot.owner, slot.entry, slot.value)
        except Exception:  # a cache whose rebuild fails on what the solver left is not the operator's
            return False
        held = {p: e.fingerprint for p, e in reader.entries.items() if _under(p, path) and (within or not e.per_product)}
        built = {p: e.fingerprint for p, e in _read_slot(fresh, slot, path).items() if within or not e.per_product}
        return held == built

    def broken(self, qp: Any) -> str:
        found = self._check(qp)
        changed = found.changed + found.bad_caches
        changed += [f"{c.__qualname__}.{name}" for c, name, value in self.methods if vars(c).get(name) is not value]
        changed += [where for _, _, where, _ in self._new_hiding(found.reader.parts)]
        return f"the solver wrote into the problem it was handed ({', '.join(changed)} changed)" if changed else ""

    def mend(self, qp: Any) -> None:
        """Put back what can be put back (class doc); right after ``broken(qp)`` it acts on
        what that read."""
        found = self._found.pop(id(qp), None) or self._check(qp)
        self._found.clear()
        for c, name, value in self.methods:
            if vars(c).get(name) is not value:
                setattr(c, name, value)
        sealed = dict(self.hiding)
        for part, name, where, _ in self._new_hiding(found.reader.parts):  # (a frozen dataclass's too)
            if where in sealed:
                object.__setattr__(part, name, sealed[where])
            else:
                object.__delattr__(part, name)
        slots = found.reader.slots
        for path in found.bad_caches + found.per_product + found.opaque:
            if path in slots:
                slots[path].put(None)  # (built again on first use)

# ---------------------------------------------------------------------------
# The verdict
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class UnreadAnswer:
    """An answer ``read_answer`` refuses in the process that made it (a worker), carried as
    the reason alone: what it held may not cross a process boundary (an object array of
    functions).  ``read_answer`` reads it as no answer, for that reason."""

    why: str


def portable_answer(p: Any, n: int) -> np.ndarray | UnreadAnswer:
    """``p`` as a worker sends it to be judged: the plain array ``read_answer`` reads (its
    dtype kept, which the judge notes), or an ``UnreadAnswer`` with the reason it refuses
    it -- so the verdict is the same whether the solve ran in a worker or in-process."""
    pf, why = read_answer(p, n)
    return UnreadAnswer(why) if pf is None else np.asarray(p)


def read_answer(p: Any, n: int) -> tuple[np.ndarray | None, str]:
    """(p as float64, "") when ``p`` is a length-``n`` vector of finite real numbers
    (float or integer dtype), else (None, what is wrong with it)."""
    if p is None:
        return None, "returned no p"
    if isinstance(p, UnreadAnswer):
        return None, p.why
    try:
        arr = np.asarray(p)
    except Exception as exc:  # an object that numpy cannot even wrap
        return None, f"returned a p that cannot be read as an array ({type(exc).__name__})"
    if arr.dtype.kind not in "biuf":
        return None, f"returned p of dtype {arr.dtype}, which is not real numbers"
    if arr.shape != (n,):
        if arr.ndim == 1:
            return None, f"returned p of wrong length {arr.size}, expected n = {n}"
        return None, f"returned p of shape {arr.shape}, expected ({n},)"
    pf = arr.astype(np.float64, copy=False)
    if not np.all(np.isfinite(pf)):
        bad = int(np.count_nonzero(~np.isfinite(pf)))
        return None, f"p has {bad} NaN/inf entr{'y' if bad == 1 else 'ies'} of {n}"
    return pf, ""


def judge(inst: ContactInstance, p: Any, claimed: bool, check_tol: float, p_ref: np.ndarray | None = None,
          p_tol: float | None = None, analytic_load: float | None = None, *, tampered: str = "",
          multiplier: float | None = None) -> Verdict:
    """The verdict on answer ``p`` of instance ``inst`` (module doc).  ``claimed`` is the
    solver's own convergence claim; ``p_ref`` an exact reference answer; ``p_tol`` the
    allowed ||p - p_ref||_inf / ||p_ref||_inf for a "pass" (None: not checked);
    ``tampered`` what ``ProblemSeal.broken`` found the solver changed, or why the problem
    is not the harness's to judge (threads the solver left running; "" nothing);
    ``multiplier`` the approach Delta the solver reports with its answer under load
    control (``answer_report``).
    ``inst`` must be the harness's own copy of the problem; ``check_tol`` a finite number
    > 0 (an infinite one would pass p = 0, a NaN fail everything); ``claimed`` a bool,
    Python's or NumPy's (the text "no" is no claim either way); ``p_ref`` None or a
    length-n vector of finite real numbers; ``p_tol`` None or a finite number > 0.  Else
    a one-line ``ProblemInputError`` naming the input (``_checked_inputs``)."""
    claimed, p_ref = _checked_inputs(inst, claimed, check_tol, p_ref, p_tol)
    if tampered:
        verdict = _failed(claimed, tampered, reading="wrong", kind="tampered")
        verdict.tampered = True
        return verdict
    pf, why = read_answer(p, inst.n)
    if pf is None:
        return _failed(claimed, why)
    problems: list[str] = []
    kinds: list[str] = []
    ubar_dtype = np.asarray(inst.qp.ubar).dtype
    if np.asarray(p).dtype != np.float64:
        problems.append(f"returned {np.asarray(p).dtype} p (input ubar was {ubar_dtype})")
        kinds.append("dtype")
    kkt = answer_report(inst, pf, multiplier)
    with np.errstate(all="ignore"):  # a huge answer's load may overflow: a figure, not a verdict
        figures = answer_figures(inst, pf, kkt, p_ref, analytic_load, check_tol)
    solved = kkt.passes(check_tol)
    if not solved:
        value, limit = shown_apart(kkt.kkt_error, check_tol)
        problems.append(f"kkt_error {value} > check_tol {limit}")
        kinds.append("kkt")
    if p_ref is not None and p_tol is not None and not near_reference(pf, p_ref, figures["p_rel_error"], p_tol,
                                                                      kkt.p_scale):
        value, limit = shown_apart(figures["p_rel_error"], p_tol)
        problems.append(f"p is {value} off the exact reference (allowed {limit})")
        kinds.append("reference")
    reading = "pass" if not problems else ("wrong" if claimed else "unconverged")
    return Verdict("solved" if solved else "inaccurate", reading, claimed, kkt, figures, problems, kinds=kinds)


def _checked_inputs(inst: ContactInstance, claimed: Any, check_tol: float, p_ref: Any,
                    p_tol: float | None) -> tuple[bool, np.ndarray | None]:
    """``judge``'s inputs checked (its doc): the claim as a bool, p_ref as float64 or None."""
    check_positive("the judge's check_tol", check_tol)
    if p_tol is not None:
        check_positive("the judge's p_tol", p_tol)
    if not isinstance(claimed, (bool, np.bool_)):
        raise ProblemInputError(f"the judge's claimed must be a bool (True or False), got "
                                f"{printable_excerpt(repr(claimed))} of type {type(claimed).__name__}")
    if p_ref is None:
        return bool(claimed), None
    ref, why = read_answer(p_ref, inst.n)  # (an answer's own rule, but for booleans: no forces)
    if ref is not None and np.asarray(p_ref).dtype.kind == "b":
        ref, why = None, "booleans"
    if ref is None:
        raise ProblemInputError(f"the judge's p_ref must be a length-{inst.n} vector of finite real numbers, read as an "
                                f"answer: {why}")
    return bool(claimed), ref


def near_reference(p: np.ndarray, p_ref: np.ndarray, rel_error: float, p_tol: float, p_s: float) -> bool:
    """Whether ``p`` is within ``p_tol`` of the reference: relatively (``rel_error``,
    ||p - p_ref||_inf / ||p_ref||_inf), or absolutely on the problem's force scale,
    ||p - p_ref||_inf <= p_tol p_s -- a reference of forces far below p_s (a subnormal
    one, say 2.5e-324 that its float64 answer rounds to 0) is not read digit by digit."""
    if rel_error <= p_tol:
        return True
    with np.errstate(all="ignore"):
        off = float(np.max(np.abs(p - np.asarray(p_ref, dtype=np.float64)), initial=0.0))
    return math.isfinite(p_s) and off <= p_tol * p_s


def answer_report(inst: ContactInstance, p: np.ndarray, multiplier: float | None = None) -> KKTReport:
    """The KKT figures of answer ``p`` (``kkt_check``).  Under load control the approach
    Delta is part of the answer: the figures at the Delta the judge fits from p
    (``constraints.fit_multiplier``) and, where the solver reports a finite one, at that
    Delta -- the one it stopped on -- whichever is smaller.  Either is a certificate: with
    every figure small at some Delta, p is near the answer, whoever named the Delta."""
    return kkt_check(inst, p, None, reported_multiplier(multiplier))


def reported_multiplier(value: Any) -> float | None:
    """The approach a solver reports, as a float: a real number or a 0-d array of one
    (NumPy's or a device's, read with ``item``), if finite; else None (not reported)."""
    if getattr(value, "shape", None) == () and hasattr(value, "item"):
        value = value.item()
    if not is_real(value) or not math.isfinite(value):
        return None
    return float(value)


def shown_apart(value: float, limit: float) -> tuple[str, str]:
    """``value`` and the ``limit`` it is compared with, each to the same number of
    significant digits -- 3, or as many more as tell them apart -- so that a message
    "value > limit" never reads as its opposite or as a tie."""
    for digits in range(3, 18):
        shown = f"{value:.{digits}g}", f"{limit:.{digits}g}"
        if shown[0] != shown[1]:
            return shown
    return repr(float(value)), repr(float(limit))


def _failed(claimed: bool, why: str, reading: str | None = None, kind: str = "answer") -> Verdict:
    """The verdict on no answer: status "failed", wrong if claimed (or ``reading``)."""
    figures = {"kkt_error": math.inf, "error": why}
    return Verdict("failed", reading or ("wrong" if claimed else "unconverged"), claimed, None, figures, [why],
                   kinds=[kind])


def answer_figures(inst: ContactInstance, p: np.ndarray, kkt: KKTReport, p_ref: np.ndarray | None,
                   analytic_load: float | None, check_tol: float = CONTACT_TOL) -> dict[str, Any]:
    """The table's figures of an answer: KKT figures, load, contact fraction and the
    errors against the reference / closed form (column names of ``harness.table.schema``).
    The contact fraction and its flag ``contact_uncertain`` are read at the judge's
    ``check_tol`` (``ContactInstance.contact_mask``: p_i > check_tol x p_s), and under a
    hardness so are the plastic share and its flag ``plastic_uncertain``
    (``problems.plastic_share``)."""
    load = inst.load(p)
    out: dict[str, Any] = {
        "primal_residual": kkt.primal,
        "dual_residual": kkt.dual,
        "complementarity": kkt.complementarity,
        "complementarity_sum": kkt.complementarity_sum,
        "kkt_error": kkt.kkt_error,
        "objective": kkt.objective,
        "load": load,
        "dim_load": inst.dimensionless_load(p),
        "contact_fraction": inst.contact_fraction(p, check_tol),
        "contact_uncertain": inst.contact_uncertain(p, check_tol),
    }
    constraints = inst.qp.constraints
    if constraints.load_control:  # the answer's approach: the equality's multiplier the figures were read at
        out["delta"] = kkt.multiplier
        out["load_residual"] = kkt.equality
    if constraints.bounded:
        out["plastic_fraction"] = inst.plastic_fraction(p, check_tol)
        out["plastic_uncertain"] = plastic_uncertain(inst, p, check_tol)
    if p_ref is not None:
        out["p_rel_error"] = relative_error(p, p_ref)
        out["load_rel_error"] = relative_load_error(load, float(np.sum(p_ref)))
    if analytic_load is not None and math.isfinite(analytic_load):
        out["analytic_load_rel_error"] = relative_load_error(load, analytic_load)
        if p_ref is None:
            out["load_rel_error"] = out["analytic_load_rel_error"]
    return out
