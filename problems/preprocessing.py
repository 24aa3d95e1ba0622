"""What was done to a measured height map between its file and the problem: the
``MapPreprocessing`` record.

``problems.io.load_surface`` produces one for every map it reads and hangs it on the
surface (``Surface.preprocessing``); a ``ContactInstance`` carries it through its surface.
It holds

* which map: the file's base name (``source``) and where it was read (``path``, absolute,
  links resolved: one file by any path), its format and channel (its name, ``channel``,
  and its index in the file, ``channel_index``: a name two channels share picks neither),
  and a content hash of the raw heights as read (``raw_sha256``: float64, C order, every
  missing point the same NaN, with the shape), so the same map given by two paths is
  recognisably the same, and the same hash of the heights as solved (``solved_sha256``, in
  metres after the unit, fill, detrend and crop: what the cleaning code made of it);
* how it was read: the unit of the file's numbers and where it came from, the spacing per
  axis and where it came from, N0 x N1 as read and as solved, the lengths;
* what was changed: the NaN rule with the count and share of filled points and the height
  written into them, and how many of them lie in the map as solved (a crop may leave them
  out: ``filled_solved``, the table's ``nan_filled``); the detrend rule with the tilt measured, the mean removed and the
  removed plane's slope per axis; the crop rule and what it did;
* the warnings the loader raised (each also announced once per process as a
  ``UserWarning``).

``key`` hashes ``raw_sha256`` with every option that changes the problem (``key_options``:
the NaN, detrend and crop rules, the metres per file number, the spacing per axis, the
channel).  It names the instance (``instance_name``): ``file-<base name>-<key[:8]>`` (the
base name in plain letters, ``name_text``), so ``--detrend none`` and ``--detrend plane``
give different names and two paths to one map the same.  ``columns`` gives the table's columns of a map (harness/table/schema.py), from
which, with the file, the problem is rebuilt: docs/columns.md.

The removed plane, in the map's own coordinates x0 = i d0, x1 = j d1 (i rows, j columns,
metres from the first point): z_removed = removed_mean + s0 (x0 - c0) + s1 (x1 - c1), with
(c0, c1) the centre of the map as read ((N0 - 1) d0 / 2, (N1 - 1) d1 / 2) and
(s0, s1) = ``removed_slope`` (rise per length).  "mean" removes ``removed_mean`` only;
"none" removes nothing (both None).
"""

from __future__ import annotations

import hashlib
import json
import re
import unicodedata
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

#: Hex digits of ``key`` in an instance name.
NAME_KEY_DIGITS = 8
#: Hex digits of ``raw_sha256`` (``solved_sha256``) in the table's ``surface_hash``
#: (``solved_hash``) column.
TABLE_HASH_DIGITS = 16
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
#: Letters with no decomposition into a plain letter and a mark, written in plain letters.
_LETTERS = str.maketrans({"µ": "u", "μ": "u", "ß": "ss", "æ": "ae", "Æ": "AE", "ø": "o", "Ø": "O", "œ": "oe",
                          "Œ": "OE", "ł": "l", "Ł": "L", "đ": "d", "Đ": "D", "ð": "d", "þ": "th"})


def raw_heights_sha256(z: np.ndarray) -> str:
    """sha256 (hex) of a height map as read: its shape, then its heights as float64 in C
    order with every missing point the same NaN (so NaN payloads and memory layout do
    not change the hash)."""
    a = np.ascontiguousarray(np.asarray(z, dtype=np.float64))
    a = np.where(np.isnan(a), np.nan, a)
    h = hashlib.sha256(f"{a.shape[0]}x{a.shape[1]}:".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def options_key(raw_sha256: str, options: dict[str, Any]) -> str:
    """sha256 (hex) of the raw heights' hash and the options that change the problem."""
    text = json.dumps([raw_sha256, options], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class MapPreprocessing:
    """Everything the loader did to one measured map (module doc).  Lengths in metres,
    heights in metres as solved."""

    source: str
    path: str
    raw_sha256: str
    key: str
    format: str
    channel: str | None
    height_unit: str
    unit_from: str
    metres_per_unit: float
    shape_read: tuple[int, int]
    shape: tuple[int, int]
    spacing: tuple[float, float]
    spacing_from: str
    nan_rule: str
    filled: int
    filled_fraction: float
    fill_value: float | None
    detrend: str
    tilt: float
    removed_mean: float | None
    removed_slope: tuple[float, float] | None
    crop: str
    crop_done: str
    warnings: tuple[str, ...] = ()
    #: What the filled points' ``fill_value`` is measured from: "zero" (the heights as read)
    #: or "the measured points' plane" (io.fill_missing, with detrend "plane").
    fill_relative_to: str = "zero"
    #: The index of ``channel`` in the file (``load_surface``'s ``channel``); None for a file
    #: of no channels (.npy, text).
    channel_index: int | None = None
    #: How many of the ``filled`` points lie in the map as solved (a crop may leave some or
    #: all of them out of the problem); None: ``filled``.
    filled_solved: int | None = None
    #: ``raw_heights_sha256`` of the heights as solved (metres, after the unit, the fill, the
    #: detrend and the crop): pins the cleaning code's result; "" where not recorded.
    solved_sha256: str = ""

    @property
    def filled_in_problem(self) -> int:
        """The filled points of the map as solved (``filled_solved``; ``filled`` where not
        recorded): the table's ``nan_filled``."""
        return self.filled if self.filled_solved is None else self.filled_solved

    @property
    def lengths(self) -> tuple[float, float]:
        """(N0 d0, N1 d1) of the map as solved."""
        return (self.shape[0] * self.spacing[0], self.shape[1] * self.spacing[1])

    @property
    def instance_name(self) -> str:
        """``file-<base name>-<key[:8]>``: the name of an instance on this map as prepared,
        the base name as ``name_text`` writes it."""
        return f"file-{name_text(self.source)}-{self.key[:NAME_KEY_DIGITS]}"

    def as_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (meta.json's ``surface_preprocessing`` entries), with the
        lengths and the instance name."""
        out = asdict(self)
        for k in ("shape_read", "shape", "spacing", "removed_slope", "warnings"):
            out[k] = None if out[k] is None else list(out[k])
        out["lengths"] = list(self.lengths)
        out["instance_name"] = self.instance_name
        return out

    def columns(self) -> dict[str, Any]:
        """The table's columns of the map (harness/table/schema.py)."""
        slope = self.removed_slope or (float("nan"), float("nan"))
        return {"surface_source": self.source, "surface_hash": self.raw_sha256[:TABLE_HASH_DIGITS],
                "solved_hash": self.solved_sha256[:TABLE_HASH_DIGITS],
                "height_unit": self.height_unit, "nan_rule": self.nan_rule, "nan_filled": self.filled_in_problem,
                "detrend": self.detrend,
                "removed_mean": float("nan") if self.removed_mean is None else self.removed_mean,
                "removed_slope0": slope[0], "removed_slope1": slope[1], "crop": self.crop,
                "channel_index": self.channel_index}


def name_text(base_name: str) -> str:
    """A file's base name in the characters of an instance name (A-Z a-z 0-9 . _ -):
    accented letters as their plain letter ("Höhe" -> "Hohe"; ``_LETTERS``: "µm" -> "um",
    "ß" -> "ss", ...), every other run of characters as "_" (spaces, slashes, ...);
    where a character had no plain letter (a name in another
    script), followed by "-" and ``NAME_KEY_DIGITS`` hex digits of the name's sha256, so
    that two such names stay apart."""
    spelled = base_name.translate(_LETTERS)
    plain = "".join(c for c in unicodedata.normalize("NFKD", spelled) if not unicodedata.combining(c))
    text = _UNSAFE.sub("_", plain)
    if plain.isascii():
        return text
    return f"{text}-{hashlib.sha256(base_name.encode('utf-8')).hexdigest()[:NAME_KEY_DIGITS]}"


def key_options(*, nan: str, detrend: str, crop: str, metres_per_unit: float, spacing: tuple[float, float],
                channel: str | None, filled_above_plane: bool = False) -> dict[str, Any]:
    """The options of a map's preparation that change the problem (hashed into ``key``);
    ``filled_above_plane``: missing points were filled relative to the measured points'
    plane (``io.fill_missing``), which names another problem than a fill on the raw heights."""
    out = {"nan": nan, "detrend": detrend, "crop": crop, "metres_per_unit": float(metres_per_unit),
           "spacing": [float(spacing[0]), float(spacing[1])], "channel": channel}
    if filled_above_plane:
        out["fill"] = "above the measured plane"
    return out


def plane_in_lengths(plane: dict[str, float], shape: tuple[int, int],
                     spacing: tuple[float, float]) -> tuple[float, tuple[float, float]]:
    """(height at the map's centre, (s0, s1) rise per length) of a plane given per index,
    z = a + c_per_row i + b_per_column j (``io.plane_fit``)."""
    n0, n1 = shape
    a, c, b = float(plane["a"]), float(plane["c_per_row"]), float(plane["b_per_column"])
    return a + c * 0.5 * (n0 - 1) + b * 0.5 * (n1 - 1), (c / spacing[0], b / spacing[1])


__all__ = [
    "MapPreprocessing",
    "NAME_KEY_DIGITS",
    "TABLE_HASH_DIGITS",
    "key_options",
    "name_text",
    "options_key",
    "plane_in_lengths",
    "raw_heights_sha256",
]
