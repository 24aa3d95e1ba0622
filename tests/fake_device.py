"""A device that is not there: arrays that refuse every implicit trip to the host.

``DeviceArray`` wraps a NumPy array the way a CuPy array holds device memory: NumPy's
functions and ufuncs dispatch to it (NEP 13/18) and return ``DeviceArray``; a host array
of one or more dimensions mixed into an operation, a host index array, an implicit
conversion (``np.asarray``) or a keyword CuPy's functions lack (``CUPY_LACKS``) raises
``TypeError``, as CuPy does; so does ``np.zeros_like(a, shape=0)``, which CuPy would
answer with an array of a's shape.  A scalar may cross
(``float``, ``int``, ``bool``, ``item``: what a device loop synchronises on); whole
arrays cross only through ``SPACE.put`` (``xp.asarray``) and ``get``, and ``TRANSFERS``
counts both.  So a solve run on ``SPACE`` proves that its loop keeps its vectors where
they live: a test counts the array transfers of a solve against its iterations.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.lib.mixins import NDArrayOperatorsMixin

from contactbench.problems.operators_gpu import ArraySpace


@dataclass
class Transfers:
    """Whole arrays moved host -> device (``uploads``) and device -> host (``downloads``),
    and scalars read on the host (``scalars``)."""

    uploads: int = 0
    downloads: int = 0
    scalars: int = 0

    def arrays(self) -> int:
        return self.uploads + self.downloads


TRANSFERS = Transfers()

#: Keywords NumPy's functions take and CuPy's do not (its reductions: ``initial``, ``where``).
CUPY_LACKS = frozenset({"initial", "where"})


def _strip(x: Any) -> Any:
    """x with every DeviceArray unwrapped (in lists, tuples and dicts too); a host array
    of one or more dimensions is refused (CuPy: "Unsupported type numpy.ndarray")."""
    if isinstance(x, DeviceArray):
        return x.a
    if isinstance(x, np.ndarray) and x.ndim > 0:
        raise TypeError(f"a host array (shape {x.shape}) mixed into a device operation")
    if isinstance(x, (list, tuple)):
        return type(x)(_strip(v) for v in x)
    if isinstance(x, dict):
        return {k: _strip(v) for k, v in x.items()}
    return x


def _wrap(x: Any) -> Any:
    """Results back on the device: arrays (0-d too) wrapped, tuples element-wise."""
    if isinstance(x, np.ndarray):
        return DeviceArray(x)
    if isinstance(x, np.generic):
        return DeviceArray(np.asarray(x))
    if isinstance(x, tuple):
        return tuple(_wrap(v) for v in x)
    if isinstance(x, list):
        return [_wrap(v) for v in x]
    return x


class DeviceArray(NDArrayOperatorsMixin):
    """An array on the fake device (module doc)."""

    __slots__ = ("a",)

    def __init__(self, a: np.ndarray) -> None:
        self.a = a

    def __array__(self, *args: Any, **kwargs: Any) -> np.ndarray:
        raise TypeError("implicit conversion of a device array to a host array")

    def __array_ufunc__(self, ufunc: Any, method: str, *inputs: Any, **kwargs: Any) -> Any:
        out = kwargs.get("out")
        kwargs = _strip(kwargs)
        result = getattr(ufunc, method)(*_strip(inputs), **kwargs)
        if out is not None:
            return out[0] if len(out) == 1 else out
        return _wrap(result)

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        unsupported = CUPY_LACKS & set(kwargs)
        if unsupported:
            raise TypeError(f"np.{func.__name__}: CuPy takes no {sorted(unsupported)}")
        if func.__name__.endswith("_like") and "shape" in kwargs and not kwargs["shape"] and kwargs["shape"] is not None:
            raise TypeError(f"np.{func.__name__}(shape={kwargs['shape']!r}): CuPy reads a false shape as the "
                            "array's own (give a tuple: shape=(0,))")
        return _wrap(func(*_strip(args), **_strip(kwargs)))

    # -- attributes and methods a loop uses --------------------------------------------
    shape = property(lambda self: self.a.shape)
    size = property(lambda self: self.a.size)
    ndim = property(lambda self: self.a.ndim)
    dtype = property(lambda self: self.a.dtype)
    nbytes = property(lambda self: self.a.nbytes)
    real = property(lambda self: DeviceArray(self.a.real))
    T = property(lambda self: DeviceArray(self.a.T))

    def __len__(self) -> int:
        return len(self.a)

    def __getitem__(self, key: Any) -> Any:
        return _wrap(self.a[_strip(key)])

    def __setitem__(self, key: Any, value: Any) -> None:
        self.a[_strip(key)] = _strip(value)

    def _scalar(self) -> Any:
        if self.a.size != 1:
            raise TypeError(f"only a one-element device array converts to a scalar, not shape {self.a.shape}")
        TRANSFERS.scalars += 1
        return self.a.reshape(()).item()

    def __float__(self) -> float:
        return float(self._scalar())

    def __int__(self) -> int:
        return int(self._scalar())

    def __bool__(self) -> bool:
        return bool(self._scalar())

    def item(self) -> Any:
        return self._scalar()

    def tolist(self) -> Any:
        """A small array read on the host in one transfer (what a loop waits on once for
        several scalars): counted as one scalar read."""
        TRANSFERS.scalars += 1
        return self.a.tolist()

    def get(self) -> np.ndarray:
        """The explicit download (CuPy's ``ndarray.get``)."""
        TRANSFERS.downloads += 1
        return self.a.copy()

    def __getattr__(self, name: str) -> Any:  # copy, astype, ravel, reshape, sum, fill, ...
        attr = getattr(self.a, name)
        if not callable(attr):
            raise AttributeError(name)
        return lambda *args, **kwargs: _wrap(attr(*_strip(args), **_strip(kwargs)))

    def __repr__(self) -> str:
        return f"DeviceArray({self.a!r})"


def _upload(a: Any, dtype: Any = None) -> DeviceArray:
    if isinstance(a, DeviceArray):
        return a if dtype is None else DeviceArray(a.a.astype(dtype, copy=False))
    TRANSFERS.uploads += 1
    return DeviceArray(np.array(a, dtype=dtype))


class _Namespace:
    """NumPy's functions (or a sub-module's) with device arrays in and out."""

    def __init__(self, module: Any) -> None:
        self._module = module

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._module, name)
        if not callable(attr):
            return attr
        return lambda *args, **kwargs: _wrap(attr(*_strip(args), **_strip(kwargs)))


class _Pool:
    """CuPy's memory pool as far as a device state uses it: ``released`` counts the calls
    that give its unused blocks back."""

    released = 0

    def free_all_blocks(self) -> None:
        self.released += 1


POOL = _Pool()

#: The fake device's array module: ``asarray`` uploads, ``fft`` runs NumPy's FFT on it.
xp = SimpleNamespace(asarray=_upload, fft=_Namespace(np.fft), __name__="fake_device",
                     get_default_memory_pool=lambda: POOL)
for _name in ("zeros", "ones", "empty", "full", "arange", "zeros_like", "ones_like", "empty_like", "full_like"):
    setattr(xp, _name, getattr(_Namespace(np), _name))
for _name in ("float32", "float64", "complex64", "complex128", "bool_", "int64", "int32"):
    setattr(xp, _name, getattr(np, _name))

#: The space a test hands ``ArrayKernelTransform.from_host``.
SPACE = ArraySpace("fake", xp, lambda a: _upload(a), lambda a: a.get())
