"""problems.io: readers round-trip each format, bad files get clear errors, cleaning
rules.  (Coarsening and the PSD power-law check: tests/problems/test_problems_coarsen.py.)"""

from __future__ import annotations

import re
import struct
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from contactbench.problems.coarsen import power_law_check
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.io import (
    SurfaceFileError,
    load_surface,
    parse_length,
    read_height_map,
    write_text,
    write_x3p,
)
from contactbench.problems.map_files import write_sdf
from contactbench.problems.surfaces import Surface
from tests.helpers import REPO

DATA = REPO / "problems" / "data"


def random_map(shape: tuple[int, int] = (12, 12), seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 1e-6, shape)


# --- round trips -----------------------------------------------------------------


def test_npy_round_trip_exact(tmp_path: Path) -> None:
    z = random_map()
    np.save(tmp_path / "a.npy", z)
    s = load_surface(tmp_path / "a.npy", length=1e-4, detrend="none")
    np.testing.assert_array_equal(s.heights, z)
    assert s.delta == pytest.approx(1e-4 / 12)
    assert s.meta["format"] == "npy" and not s.periodic


@pytest.mark.parametrize("delim", [",", ";", "\t", " "])
def test_text_round_trip_any_delimiter(tmp_path: Path, delim: str) -> None:
    z = random_map((9, 9), seed=1)
    write_text(tmp_path / "a.txt", z, delimiter=delim)
    s = load_surface(tmp_path / "a.txt", length=1.0, detrend="none")
    np.testing.assert_array_equal(s.heights, z)


def test_text_comments_and_units(tmp_path: Path) -> None:
    z = np.arange(1, 65).reshape(8, 8)
    lines = [", ".join(map(str, row)) for row in z]
    lines[1] += " # row 2"
    lines[2] += ","  # a trailing delimiter
    (tmp_path / "a.csv").write_text("# exported heights in um\n" + "\n".join(lines) + "\n")
    s = load_surface(tmp_path / "a.csv", length=8e-6, height_unit="um", detrend="none")
    np.testing.assert_allclose(s.heights, z * 1e-6)


@pytest.mark.parametrize("dtype", ["D", "F", "L", "I"])
def test_x3p_round_trip_each_data_type(tmp_path: Path, dtype: str) -> None:
    z = random_map((10, 10), seed=2)
    write_x3p(tmp_path / "a.x3p", z, 2.5e-6, data_type=dtype)
    s = load_surface(tmp_path / "a.x3p", detrend="none")  # no length: the file's own lateral size
    span = float(z.max() - z.min())
    atol = {"D": 0.0, "F": 1e-7 * span, "L": span / 2**31, "I": span / 2**15}[dtype]
    np.testing.assert_allclose(s.heights, z, rtol=0.0, atol=atol)
    assert s.delta == pytest.approx(2.5e-6, rel=1e-14)
    assert s.meta["x3p_data_type"] == dtype and s.meta["spacing_from"] == "file"


@pytest.mark.parametrize("dtype", ["D", "I"])
def test_x3p_missing_points_round_trip(tmp_path: Path, dtype: str) -> None:
    z = random_map((8, 8), seed=3)
    z[2, 3] = z[5, 5] = np.nan
    write_x3p(tmp_path / "a.x3p", z, 1e-6, data_type=dtype)
    raw = read_height_map(tmp_path / "a.x3p")
    np.testing.assert_array_equal(np.isnan(raw.z), np.isnan(z))
    span = float(np.nanmax(z) - np.nanmin(z))
    np.testing.assert_allclose(raw.z[~np.isnan(z)], z[~np.isnan(z)], atol=span / 2**15)


def test_x3p_axis_orientation_x_fastest(tmp_path: Path) -> None:
    z = np.arange(72.0).reshape(8, 9) * 1e-6  # 8 rows (y), 9 columns (x)
    write_x3p(tmp_path / "a.x3p", z, 1e-6)
    with zipfile.ZipFile(tmp_path / "a.x3p") as zf:
        xml = zf.read("main.xml").decode()
        raw = np.frombuffer(zf.read("bindata/data.bin"), "<f8")
    assert "<SizeX>9</SizeX>" in xml and "<SizeY>8</SizeY>" in xml
    np.testing.assert_array_equal(raw[:9], z[0])  # x runs fastest
    np.testing.assert_array_equal(read_height_map(tmp_path / "a.x3p").z, z)


def test_length_agreeing_with_the_file_is_accepted_disagreeing_refused(tmp_path: Path) -> None:
    write_x3p(tmp_path / "a.x3p", random_map((8, 8)), 1e-6)
    s = load_surface(tmp_path / "a.x3p", length=8e-6, detrend="none")
    assert s.delta == pytest.approx(1e-6) and "agrees" in s.meta["spacing_from"]
    with pytest.raises(SurfaceFileError, match="disagrees with the file's own side length"):
        load_surface(tmp_path / "a.x3p", length=16e-6, detrend="none")


def test_file_unit_is_converted_to_metres(tmp_path: Path) -> None:
    from SurfaceTopography import Topography

    z = random_map((8, 8), seed=6) * 1e6  # micrometres
    Topography(z.T, physical_sizes=(8.0, 8.0), unit="um").to_netcdf(str(tmp_path / "a.nc"))
    s = load_surface(tmp_path / "a.nc", detrend="none")
    np.testing.assert_allclose(s.heights, z * 1e-6, rtol=1e-15)
    assert s.delta == pytest.approx(1e-6, rel=1e-7) and s.meta["file_unit"] in ("um", "µm")


# --- bad files ---------------------------------------------------------------------


def _x3p_with_xml(path: Path, xml_edit: tuple[str, str] | None = None, drop: str | None = None,
                  data: bytes | None = None, side: int = 6) -> Path:
    write_x3p(path, random_map((side, side)), 1e-6)
    with zipfile.ZipFile(path) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    if xml_edit:
        members["main.xml"] = members["main.xml"].replace(xml_edit[0].encode(), xml_edit[1].encode())
    if drop:
        members.pop(drop)
    if data is not None:
        members["bindata/data.bin"] = data
    path.unlink()
    with zipfile.ZipFile(path, "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    return path


def _x3p_with_cz(path: Path, data_type: str, increment: str | None) -> Path:
    """An x3p of ``data_type`` heights whose CZ axis states ``increment`` (None: no increment)."""
    write_x3p(path, random_map((6, 6)), 1e-6, data_type=data_type)
    with zipfile.ZipFile(path) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    inc = "" if increment is None else f"<Increment>{increment}</Increment>"
    cz = f"<CZ><AxisType>A</AxisType><DataType>{data_type}</DataType>{inc}</CZ>"
    members["main.xml"] = re.sub(r"<CZ>.*?</CZ>", cz, members["main.xml"].decode(), flags=re.S).encode()
    path.unlink()
    with zipfile.ZipFile(path, "w") as zf:
        for n, b in members.items():
            zf.writestr(n, b)
    return path


def _sdf_stating_fewer_rows(tmp: Path, binary: bool) -> Path:
    """A 6 x 6 .sdf whose header states 4 profiles (rows) of its 6."""
    path = write_sdf(tmp / f"fewer-{'b' if binary else 'a'}.sdf", random_map((6, 6)), 1e-6, binary=binary)
    if binary:
        raw = bytearray(path.read_bytes())
        raw[44:46] = struct.pack("<H", 4)  # NumProfiles, after the magic, the dates and NumPoints
        path.write_bytes(bytes(raw))
    else:
        path.write_text(path.read_text().replace("NumProfiles = 6", "NumProfiles = 4"))
    return path


def _coordinate_files(tmp: Path) -> dict[str, tuple[Path, str]]:
    """Text files of coordinate columns that are no map: an x,z profile, and x,y,z columns
    with a point missing from their grid; and a map written with decimal commas."""
    x = np.arange(32) * 1e-6
    np.savetxt(tmp / "profile.csv", np.column_stack([x, random_map((32, 1))[:, 0]]), delimiter=",")
    yy, xx = np.mgrid[0:6, 0:6] * 1e-6
    cols = np.column_stack([xx.ravel(), yy.ravel(), random_map((6, 6)).ravel()])
    np.savetxt(tmp / "gap.csv", np.delete(cols, 14, axis=0), delimiter=",")
    (tmp / "euro.csv").write_text("-0,614752;-0,683930\n6,1e-07;-0,5\n")
    return {"an x,z profile": (tmp / "profile.csv", "an x,z profile, not a 2-D height map"),
            "x,y,z columns with a point missing": (tmp / "gap.csv", "do not fill a regular grid"),
            "decimal commas": (tmp / "euro.csv", "decimal commas are not read ('-0,614752' on line 1)")}


def bad_files(tmp: Path) -> dict[str, tuple[Path, str]]:
    """Each bad-file class -> (file, a phrase its error must contain)."""
    out: dict[str, tuple[Path, str]] = {}
    np.save(tmp / "good.npy", random_map((16, 16)))
    raw = (tmp / "good.npy").read_bytes()
    (tmp / "trunc.npy").write_bytes(raw[: len(raw) // 2])
    out["truncated npy"] = (tmp / "trunc.npy", "truncated")
    np.save(tmp / "obj.npy", np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    out["pickled npy"] = (tmp / "obj.npy", "pickle")
    (tmp / "fake.npy").write_bytes(b"these bytes are not a NumPy array")
    out["not npy at all"] = (tmp / "fake.npy", "not a .npy file")
    huge = random_map((16, 16))
    huge[3, 5] = 1e308
    np.save(tmp / "huge.npy", huge)
    out["a height whose square overflows"] = (tmp / "huge.npy", "1e+308 at index (3, 5)")
    huge_text = np.ones((8, 8))
    huge_text[7, 7] = 1e200
    np.savetxt(tmp / "huge.csv", huge_text, delimiter=",")
    out["a height whose square overflows, text"] = (tmp / "huge.csv", "overflow")
    np.save(tmp / "vec.npy", np.arange(10.0))
    out["wrong shape npy"] = (tmp / "vec.npy", "wrong shape")
    np.save(tmp / "str.npy", np.array([["a", "b"], ["c", "d"]]))
    out["non-numeric npy"] = (tmp / "str.npy", "non-numeric")
    np.save(tmp / "nan.npy", np.full((8, 8), np.nan))
    out["NaN-only"] = (tmp / "nan.npy", "NaN-only")
    (tmp / "ragged.csv").write_text("1,2,3\n4,5,6\n7,8\n")
    out["truncated text"] = (tmp / "ragged.csv", "wrong shape")
    (tmp / "words.csv").write_text("1,2\n3,abc\n")
    out["non-numeric text"] = (tmp / "words.csv", "non-numeric value 'abc' on line 2")
    (tmp / "empty.txt").write_text("# nothing\n")
    out["empty text"] = (tmp / "empty.txt", "no data rows")
    with zipfile.ZipFile(tmp / "other.x3p", "w") as zf:
        zf.writestr("readme.txt", "hello")
    out["zip not x3p"] = (tmp / "other.x3p", "main.xml")
    (tmp / "plain.x3p").write_text("not a zip")
    out["x3p not a zip"] = (tmp / "plain.x3p", "not a valid zip")
    write_x3p(tmp / "t.x3p", random_map((6, 6)), 1e-6)
    rawx = (tmp / "t.x3p").read_bytes()
    (tmp / "trunc.x3p").write_bytes(rawx[: len(rawx) - 200])
    out["truncated x3p"] = (tmp / "trunc.x3p", "zip")
    out["truncated x3p data"] = (_x3p_with_xml(tmp / "short.x3p", data=b"\0" * 100), "truncated")
    out["x3p checksum"] = (_x3p_with_xml(tmp / "md5.x3p", data=b"\0" * 288), "MD5")
    out["x3p missing data"] = (_x3p_with_xml(tmp / "nodata.x3p", drop="bindata/data.bin"), "missing")
    out["x3p profile"] = (_x3p_with_xml(tmp / "prf.x3p", ("<FeatureType>SUR", "<FeatureType>PRF")), "'SUR'")
    out["x3p bad xml"] = (_x3p_with_xml(tmp / "xml.x3p", ("</Record1>", "")), "not well-formed")
    out["x3p data longer than stated"] = (_x3p_with_xml(tmp / "small.x3p", ("<SizeX>6</SizeX>", "<SizeX>4</SizeX>")),
                                          "holds 288 bytes where main.xml states 192")
    np.save(tmp / "lie.npy", random_map((16, 16)))
    raw = (tmp / "lie.npy").read_bytes()
    (tmp / "lie.npy").write_bytes(raw.replace(b"(16, 16)", b"(8, 16) ", 1))
    out["npy data longer than its header states"] = (tmp / "lie.npy", "more data than its header's 8 x 16 values")
    out["x3p of no points"] = (_x3p_with_xml(tmp / "zero.x3p", ("<SizeX>6</SizeX>\n      <SizeY>6</SizeY>",
                                                                "<SizeX>0</SizeX>\n      <SizeY>0</SizeY>"), data=b""),
                               "grid spacing")
    (tmp / "bom.csv").write_text("\ufeff1,2\n3,x\n", encoding="utf-8")
    out["byte-order mark, then a bad value"] = (tmp / "bom.csv", "non-numeric value 'x' on line 2")
    out["x3p entities"] = (_x3p_with_xml(tmp / "dtd.x3p", ("<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"no\" ?>",
                                                          '<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "b">]>')), "DTD")
    out["binary sdf data longer than its header states"] = (_sdf_stating_fewer_rows(tmp, True),
                                                             "header states 6 x 4 values of 8 bytes")
    out["ascii sdf data longer than its header states"] = (
        _sdf_stating_fewer_rows(tmp, False), "its data region holds 36 values where its header states 6 x 4")
    out["x3p integer heights with no CZ increment"] = (_x3p_with_cz(tmp / "noinc.x3p", "L", None),
                                                       "no CZ increment")
    out["x3p negative CZ increment"] = (_x3p_with_cz(tmp / "neg.x3p", "D", "-1.0"), "upside down")
    out["x3p zero CZ increment"] = (_x3p_with_cz(tmp / "zero-z.x3p", "D", "0"), "finite number > 0")
    out.update(_coordinate_files(tmp))
    two = np.full((8, 8), np.nan)
    two[2, 3], two[5, 6] = 1e-6, -1e-6
    np.save(tmp / "two.npy", two)
    out["all but two points missing"] = (tmp / "two.npy", "62 of its 64 points are missing (NaN, 96.9%), more than 50%")
    out.update(topography_bad_files(tmp))
    out["unreadable path"] = (tmp / "does-not-exist.npy", "unreadable path")
    out["directory"] = (tmp, "unreadable path")
    return out


def topography_bad_files(tmp: Path) -> dict[str, tuple[Path, str]]:
    """The classes SurfaceTopography's formats add: line scans, profiles, channels, units, pixels."""
    import scipy.io
    from SurfaceTopography import NonuniformLineScan, Topography, UniformLineScan

    out: dict[str, tuple[Path, str]] = {}
    NonuniformLineScan(np.array([0.0, 0.1, 0.5, 1.0]), np.arange(4.0)).to_netcdf(str(tmp / "nu.nc"))
    out["non-uniform line scan"] = (tmp / "nu.nc", "non-uniform line scan")
    UniformLineScan(np.arange(10.0), 5.0, unit="um").to_netcdf(str(tmp / "ls.nc"))
    out["1-D profile"] = (tmp / "ls.nc", "1-D profile")
    scipy.io.savemat(tmp / "two.mat", {"height": random_map((6, 6)), "intensity": random_map((6, 6))})
    out["multi-channel, none chosen"] = (tmp / "two.mat", "--channel")
    Topography(random_map((6, 6)).T, physical_sizes=(6.0, 6.0), unit="V").to_netcdf(str(tmp / "volt.nc"))
    out["unit not convertible"] = (tmp / "volt.nc", "cannot be converted to metres")
    (tmp / "junk.bin").write_bytes(bytes(range(256)) * 4)
    out["unknown binary"] = (tmp / "junk.bin", "nor one SurfaceTopography recognises")
    return out


def test_every_bad_file_class_gives_a_clear_error(tmp_path: Path) -> None:
    for what, (path, phrase) in bad_files(tmp_path).items():
        with pytest.raises(SurfaceFileError) as e:
            load_surface(path, length=1e-4, detrend="none")
        msg = str(e.value)
        assert str(path) in msg, what
        assert phrase.lower() in msg.lower(), f"{what}: {msg}"
        assert isinstance(e.value, ProblemInputError)


def test_an_infinite_height_in_an_x3p_is_refused_as_in_npy_and_text(tmp_path: Path) -> None:
    """SurfaceTopography masks an inf as an undefined point, which is not a measured hole to
    fill: refused, as .npy and text refuse it."""
    import hashlib

    path = _x3p_with_xml(tmp_path / "inf.x3p", side=8)
    with zipfile.ZipFile(path) as zf:
        data = zf.read("bindata/data.bin")
    values = np.frombuffer(data, dtype="<f8").copy()
    values[7] = np.inf
    md5 = (hashlib.md5(data).hexdigest().upper(), hashlib.md5(values.tobytes()).hexdigest().upper())
    _x3p_with_xml(path, md5, data=values.tobytes(), side=8)
    with pytest.raises(SurfaceFileError, match="1 infinite heights"):
        load_surface(path, detrend="none")


def test_a_byte_order_mark_is_no_value(tmp_path: Path) -> None:
    """Spreadsheets write CSV UTF-8 with a byte-order mark: the map reads as without it."""
    z = random_map((8, 8))
    (tmp_path / "bom.csv").write_text("\ufeff" + "\n".join(",".join(repr(float(v)) for v in row) for row in z),
                                      encoding="utf-8")
    assert np.array_equal(read_height_map(tmp_path / "bom.csv").z, z)


def test_x_y_z_columns_of_a_regular_grid_are_read_as_that_grid(tmp_path: Path) -> None:
    """3 columns of at least XYZ_MIN_ROWS rows whose x and y take evenly spaced values, every
    point of the grid once (in any order), are that grid: rows in increasing y, columns in
    increasing x, the spacings the coordinates' steps, x, y, z in one unit.  A narrow
    matrix of heights (N x 3, N x 2, 3 x 3) stays a matrix, refused as one: too narrow."""
    z = random_map((8, 10), seed=11)
    yy, xx = np.mgrid[0:8, 0:10]
    cols = np.column_stack([xx.ravel() * 2e-6, yy.ravel() * 1e-6 + 5e-6, z.ravel()])
    np.savetxt(tmp_path / "xyz.csv", cols[np.random.default_rng(0).permutation(80)], delimiter=",", fmt="%.17g")
    s = load_surface(tmp_path / "xyz.csv", detrend="none")
    np.testing.assert_array_equal(s.heights, z)
    assert s.spacing == pytest.approx((1e-6, 2e-6), rel=1e-12) and s.meta["spacing_from"] == "file"
    with pytest.raises(SurfaceFileError, match="disagrees with the file's own side length"):
        load_surface(tmp_path / "xyz.csv", length=1e-3, detrend="none")
    np.savetxt(tmp_path / "xyz_um.txt", cols * 1e6, fmt="%.12g")  # micrometres, white space, rounded
    um = load_surface(tmp_path / "xyz_um.txt", height_unit="um", detrend="none")
    np.testing.assert_allclose(um.heights, z, rtol=0.0, atol=1e-17)
    assert um.spacing == pytest.approx((1e-6, 2e-6), rel=1e-9)
    for shape in [(40, 3), (40, 2), (3, 3)]:
        write_text(tmp_path / "narrow.csv", random_map(shape, seed=12))
        with pytest.raises(SurfaceFileError, match=f"wrong shape: {shape[0]} x {shape[1]} points; a map needs"):
            read_height_map(tmp_path / "narrow.csv")


@pytest.mark.parametrize("binary", [True, False])
def test_an_sdf_reads_back_with_its_spacings_and_a_binary_one_may_end_in_a_text_trailer(
        tmp_path: Path, binary: bool) -> None:
    z = random_map((8, 10), seed=13)
    path = write_sdf(tmp_path / "a.sdf", z, (2e-6, 1e-6), binary=binary)
    if binary:
        path.write_bytes(path.read_bytes() + b"*\nComment = a trailer\n*\n")
    s = load_surface(path, detrend="none")
    np.testing.assert_allclose(s.heights, z, rtol=1e-14, atol=0.0)
    assert s.spacing == pytest.approx((2e-6, 1e-6), rel=1e-12)


def _gwy(path: Path, channels: list[tuple[str, np.ndarray]], side: float) -> Path:
    """A Gwyddion .gwy file (a serialised GwyContainer) of 2-D channels (title, heights in
    metres), each side x side metres."""
    def cstr(text: str) -> bytes:
        return text.encode() + b"\0"

    def item(key: str, kind: str, payload: bytes) -> bytes:
        return cstr(key) + kind.encode() + payload

    def obj(cls: str, items: list[bytes]) -> bytes:
        body = b"".join(items)
        return cstr(cls) + struct.pack("<I", len(body)) + body

    metre = obj("GwySIUnit", [item("unitstr", "s", cstr("m"))])
    items = []
    for k, (title, z) in enumerate(channels):
        field = obj("GwyDataField", [
            item("xres", "i", struct.pack("<i", z.shape[1])), item("yres", "i", struct.pack("<i", z.shape[0])),
            item("xreal", "d", struct.pack("<d", side)), item("yreal", "d", struct.pack("<d", side)),
            item("si_unit_xy", "o", metre), item("si_unit_z", "o", metre),
            item("data", "D", struct.pack("<I", z.size) + z.astype("<f8").tobytes())])
        items += [item(f"/{k}/data", "o", field), item(f"/{k}/data/title", "s", cstr(title))]
    path.write_bytes(b"GWYP" + obj("GwyContainer", items))
    return path


def test_a_channel_name_two_channels_share_is_ambiguous_and_an_index_chooses(tmp_path: Path) -> None:
    z, w = random_map((8, 8), seed=14), random_map((8, 8), seed=15)
    path = _gwy(tmp_path / "two.gwy", [("Height", z), ("Height", w)], 8e-6)
    with pytest.raises(SurfaceFileError, match=r"2 channels are named 'Height' \(indices 0, 1.*choose one by index"):
        load_surface(path, channel="Height", detrend="none")
    np.testing.assert_allclose(load_surface(path, channel=1, detrend="none").heights, w, rtol=1e-15)


def test_a_mostly_missing_map_is_refused_and_a_share_never_rounds_to_0_or_100_percent(tmp_path: Path) -> None:
    """More than half of the points missing (MAX_MISSING_FRACTION) is refused; half is
    filled.  A share that is not exactly 0 or 1 reads "<0.1%" or ">99.9%"."""
    from contactbench.problems.io import MAX_MISSING_FRACTION, share_text

    assert MAX_MISSING_FRACTION == 0.5
    assert (share_text(1, 4096), share_text(4095, 4096), share_text(0, 9), share_text(9, 9)) == (
        "<0.1%", ">99.9%", "0.0%", "100.0%")
    z = random_map((64, 64))
    z[0, 0] = np.nan
    np.save(tmp_path / "one.npy", z)
    with pytest.warns(UserWarning, match=r"1 missing points \(<0\.1%\)"):
        load_surface(tmp_path / "one.npy", length=64e-6, detrend="none")
    z[:, :32] = np.nan  # half
    np.save(tmp_path / "half.npy", z)
    with pytest.warns(UserWarning, match=r"2048 missing points \(50\.0%\)"):
        load_surface(tmp_path / "half.npy", length=64e-6, detrend="none")
    z[:] = np.nan
    z[3, 4], z[40, 50] = 1e-6, -1e-6
    np.save(tmp_path / "two.npy", z)
    with pytest.raises(SurfaceFileError, match=r"4094 of its 4096 points are missing \(NaN, >99\.9%\), more than 50%"):
        load_surface(tmp_path / "two.npy", length=64e-6)


def test_a_nan_only_map_is_refused_before_any_numpy_warning(tmp_path: Path) -> None:
    np.save(tmp_path / "nan.npy", np.full((8, 8), np.nan))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SurfaceFileError, match="NaN-only"):
            load_surface(tmp_path / "nan.npy", length=8e-6, detrend="plane")


def test_text_or_npy_without_length_asks_for_it(tmp_path: Path) -> None:
    np.save(tmp_path / "a.npy", random_map())
    with pytest.raises(ProblemInputError, match="length"):
        load_surface(tmp_path / "a.npy", detrend="none")


# --- cleaning ----------------------------------------------------------------------


def test_nan_rules(tmp_path: Path) -> None:
    z = np.arange(64.0).reshape(8, 8)
    z[0, 0] = np.nan
    np.save(tmp_path / "a.npy", z)
    with pytest.warns(UserWarning, match="1 missing"):
        s = load_surface(tmp_path / "a.npy", length=8.0, detrend="none")
    assert s.heights[0, 0] == pytest.approx(np.nanmean(z)) and s.meta["nan_points"] == 1
    with pytest.warns(UserWarning):
        assert load_surface(tmp_path / "a.npy", length=8.0, nan="fill-min", detrend="none").heights[0, 0] == 1.0
    with pytest.warns(UserWarning):
        assert load_surface(tmp_path / "a.npy", length=8.0, nan="fill-nearest", detrend="none").heights[0, 0] in (1.0, 8.0)
    with pytest.raises(SurfaceFileError, match="nan='error'"):
        load_surface(tmp_path / "a.npy", length=8.0, nan="error", detrend="none")


@pytest.mark.parametrize("rule", ["fill-mean", "fill-min", "fill-nearest"])
def test_a_hole_in_a_tilted_map_is_filled_along_the_tilt_not_above_it(tmp_path: Path, rule: str) -> None:
    """A tilt below the rms slope (no warning) and a hole at the high corner: filled at one
    level, the hole became the summit once the plane was removed, and a small load touched
    only filled points.  Filled relative to the measured points' plane, the filled points
    lie within the measured heights (fill-min: at the lowest), and the record says so."""
    rough = random_map((32, 32), seed=7)
    rough *= 1e-6 / rough.std()
    yy, xx = np.mgrid[0:32, 0:32]
    z = rough + 0.16 * 1e-6 * xx  # rise per column: a tilt of 0.16 of the spacing 1 um
    z[:4, 28:] = np.nan  # the high corner
    np.save(tmp_path / "tilted.npy", z)
    with pytest.warns(UserWarning, match="relative to the measured points' plane"):
        s = load_surface(tmp_path / "tilted.npy", length=32e-6, nan=rule)
    filled, measured = s.heights[:4, 28:], np.delete(s.heights.ravel(), (yy[:4, 28:] * 32 + xx[:4, 28:]).ravel())
    assert filled.max() < measured.max()
    if rule == "fill-min":
        assert filled.max() <= measured.min() + 1e-9 * measured.std()
    assert s.meta["fill_relative_to"] == s.preprocessing.fill_relative_to == "the measured points' plane"
    flat = load_surface(tmp_path / "tilted.npy", length=32e-6, nan=rule, detrend="none")
    assert flat.meta["fill_relative_to"] == "zero"  # the tilt is kept, and the fill is on the heights as read
    assert s.preprocessing.key != flat.preprocessing.key


def test_plane_detrend_removes_tilt_exactly(tmp_path: Path) -> None:
    rough = random_map((16, 16), seed=4)
    yy, xx = np.mgrid[0:16, 0:16]
    np.save(tmp_path / "a.npy", rough + 3e-6 + 2e-7 * xx - 1e-7 * yy)
    s = load_surface(tmp_path / "a.npy", length=1.0, detrend="plane")
    yyf, xxf = yy.ravel(), xx.ravel()
    A = np.column_stack([np.ones(256), xxf, yyf])
    coef, *_ = np.linalg.lstsq(A, s.heights.ravel(), rcond=None)
    np.testing.assert_allclose(coef, 0.0, atol=1e-20)
    assert s.meta["removed_plane"]["b_per_column"] == pytest.approx(2e-7, rel=0.2)


def test_non_square_maps_are_kept_unless_a_crop_is_asked(tmp_path: Path) -> None:
    z = random_map((8, 12), seed=5)
    np.save(tmp_path / "a.npy", z)
    kept = load_surface(tmp_path / "a.npy", length=8.0, detrend="none")
    np.testing.assert_array_equal(kept.heights, z)
    assert kept.shape == (8, 12) and kept.spacing == (1.0, 1.0) and kept.lengths == (8.0, 12.0)
    with pytest.warns(UserWarning, match="cropped 8x12"):
        c = load_surface(tmp_path / "a.npy", length=8.0, crop="square", detrend="none")
    np.testing.assert_array_equal(c.heights, z[:, 2:10])
    assert c.delta == 1.0 and "cropped" in c.meta["crop"]  # the length is the map's: the crop keeps the spacing
    with pytest.warns(UserWarning, match="padded"):
        p = load_surface(tmp_path / "a.npy", length=8.0, crop="pad-square", detrend="none")
    assert p.N == 12 and p.delta == 1.0
    assert "the nominal area A0 grows by a factor 1.5" in p.meta["crop"]  # 12 x 12 over 8 x 12 points
    np.testing.assert_array_equal(p.heights[:8], z)
    assert np.all(p.heights[8:] == z.min())


def test_a_file_with_rectangular_pixels_keeps_them(tmp_path: Path) -> None:
    """x is axis 1 of a Surface (rows = y): a file of 8 x 8 points over 8 um (x) by 16 um (y)
    has spacings (2 um, 1 um) along (axis 0, axis 1)."""
    from SurfaceTopography import Topography

    z = random_map((8, 8))
    Topography(z.T, physical_sizes=(8e-6, 16e-6), unit="m").to_x3p(str(tmp_path / "pix.x3p"))
    s = load_surface(tmp_path / "pix.x3p", detrend="none")
    assert s.spacing == pytest.approx((2e-6, 1e-6)) and s.lengths == pytest.approx((16e-6, 8e-6))
    np.testing.assert_allclose(s.heights, z, rtol=0, atol=1e-15)
    assert load_surface(tmp_path / "pix.x3p", length=(16e-6, 8e-6), detrend="none").spacing == pytest.approx(s.spacing)
    with pytest.raises(SurfaceFileError, match="along axis 0 disagrees"):
        load_surface(tmp_path / "pix.x3p", length=8e-6)  # square pixels: 8 um along axis 0, the file says 16


def test_length_per_axis_gives_rectangular_pixels(tmp_path: Path) -> None:
    z = random_map((8, 10), seed=5)
    np.save(tmp_path / "a.npy", z)
    s = load_surface(tmp_path / "a.npy", length=(4.0, 20.0), detrend="none")
    assert s.spacing == (0.5, 2.0) and s.lengths == (4.0, 20.0)
    with pytest.raises(ProblemInputError, match="L1"):
        load_surface(tmp_path / "a.npy", length=(3.0, -1.0), detrend="none")
    with pytest.raises(ProblemInputError, match="L0 or \\(L0, L1\\)"):
        load_surface(tmp_path / "a.npy", length=(3.0, 1.0, 2.0))  # type: ignore[arg-type]


@pytest.mark.parametrize("text,expected", [("1e-4", 1e-4), ("1e-4, 2e-4", (1e-4, 2e-4))])
def test_parse_length(text: str, expected: object) -> None:
    assert parse_length(text) == expected


@pytest.mark.parametrize("text", ["", "a", "1,2,3", "-1", "nan", "inf", "1e-4,0", "1_0e-7", "1e-4,2_0e-5",
                                  "\u0661e-4"])
def test_parse_length_refuses_bad_text(text: str) -> None:
    with pytest.raises(ProblemInputError):
        parse_length(text)


def test_tilt_larger_than_the_rms_slope_warns_removed_or_not(tmp_path: Path) -> None:
    rough = random_map((16, 24), seed=6)
    rough *= 1e-3 / Surface(rough, 1.0).rms_slope()  # rms slope 1e-3 at unit spacing
    _, xx = np.mgrid[0:16, 0:24]
    np.save(tmp_path / "t.npy", rough + 0.05 * xx)
    with pytest.warns(UserWarning, match="tilted by .* the tilt was removed"):
        s = load_surface(tmp_path / "t.npy", length=16.0)
    assert s.meta["tilt"] == pytest.approx(0.05, rel=0.05) and s.rms_slope() < 0.05
    with pytest.warns(UserWarning, match="NOT removed"):
        load_surface(tmp_path / "t.npy", length=16.0, detrend="none")
    np.save(tmp_path / "flat.npy", rough + 1e-9 * xx)  # a tilt below the roughness: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_surface(tmp_path / "flat.npy", length=16.0)


def test_bad_option_values_are_named() -> None:
    with pytest.raises(ProblemInputError, match="crop"):
        load_surface("x.npy", 1.0, crop="stretch")  # type: ignore[arg-type]
    with pytest.raises(ProblemInputError, match="detrend"):
        load_surface("x.npy", 1.0, detrend="quadric")  # type: ignore[arg-type]
    with pytest.raises(ProblemInputError, match="nan"):
        load_surface("x.npy", 1.0, nan="zero")  # type: ignore[arg-type]


def test_shipped_samples_load() -> None:
    with pytest.warns(UserWarning):
        x3p = load_surface(DATA / "solar-10x-like.x3p", detrend="plane")
    assert x3p.N == 128 and x3p.delta == pytest.approx(1e-3 / 128)
    with pytest.warns(UserWarning, match="cropped"):
        npy = load_surface(DATA / "solar-100x-like.npy", length=97.5e-6, detrend="plane", crop="square")
    assert npy.N == 96
    csv = load_surface(DATA / "ground-like-um.csv", length=5e-4, height_unit="um", detrend="none")
    assert 0.3e-6 < csv.rms_height < 3e-6
    assert not power_law_check(x3p).power_law  # roll-off
    assert power_law_check(npy).power_law
    total = sum(f.stat().st_size for f in DATA.iterdir() if f.is_file())
    assert total < 400_000


# --- round trips across formats, through the loader the CLI uses ---------------------

ROUND_TRIP_N = 32
ROUND_TRIP_L = 64e-6


def round_trip_surface() -> np.ndarray:
    from contactbench.problems.surfaces import rmd_surface_n

    return rmd_surface_n(ROUND_TRIP_N, 0.7, length=ROUND_TRIP_L, rms_height=1e-6, seed=3).heights


def write_every_format(tmp: Path, z: np.ndarray) -> dict[str, Path]:
    """The same map in each format: SurfaceTopography's writers (x3p, gwy, NetCDF) and
    numpy/scipy (.npy, .mat), and text."""
    import scipy.io
    from contactbench.problems.io import write_topography

    d = ROUND_TRIP_L / ROUND_TRIP_N
    np.save(tmp / "s.npy", z)
    scipy.io.savemat(tmp / "s.mat", {"heights": z})
    write_text(tmp / "s.csv", z)
    return {"npy": tmp / "s.npy", "mat": tmp / "s.mat", "text": tmp / "s.csv",
            "x3p": write_topography(tmp / "s.x3p", z, d, "x3p"),
            "gwy": write_topography(tmp / "s.gwy", z, d, "gwy"),
            "netcdf": write_topography(tmp / "s.nc", z, d, "netcdf")}


def exact_sweep(path: Path, length: float | None) -> list[np.ndarray]:
    """The exact contact pressures of a 2-step paper-sweep on ``path`` (the scene's own
    loading: problems/scenes/core.surface_from_params -> problems/io.load_surface)."""
    from contactbench.problems.lcp import exact_solution
    from contactbench.problems.scenes import SceneConfig, get_scene

    scene = get_scene("paper-sweep")
    cfg = scene.config(SceneConfig(surface_path=str(path), length=length, steps=2))
    (spec,) = scene.instances(cfg)
    seq = scene.build(spec)
    out = []
    for k in range(len(seq)):
        qp = seq.at(k).qp
        out.append(exact_solution(qp.H.to_dense(), qp.ubar).p)
    return out


def test_every_format_round_trips_heights_size_and_contact_solution(tmp_path: Path) -> None:
    z = round_trip_surface()
    files = write_every_format(tmp_path, z)
    reference = exact_sweep(files["npy"], ROUND_TRIP_L)
    for fmt, path in files.items():
        states_size = fmt in ("x3p", "gwy", "netcdf")
        s = load_surface(path, None if states_size else ROUND_TRIP_L, detrend="none")
        np.testing.assert_allclose(s.heights, z, rtol=1e-15, atol=0.0, err_msg=fmt)
        assert s.length == pytest.approx(ROUND_TRIP_L, rel=1e-7), fmt  # NetCDF stores sizes in float32
        # the same contact solution as the .npy original, to round-off (the length given,
        # so the float32 size of NetCDF does not enter)
        for p, p_ref in zip(exact_sweep(path, ROUND_TRIP_L), reference):
            np.testing.assert_allclose(p, p_ref, rtol=1e-12, atol=1e-12 * float(np.max(p_ref)), err_msg=fmt)


def test_mat_channel_is_chosen_by_name_or_index(tmp_path: Path) -> None:
    import scipy.io

    z, w = random_map((8, 8), seed=8), random_map((8, 8), seed=9)
    scipy.io.savemat(tmp_path / "two.mat", {"height": z, "intensity": w})
    np.testing.assert_array_equal(load_surface(tmp_path / "two.mat", 8e-6, channel="intensity", detrend="none").heights, w)
    names = [load_surface(tmp_path / "two.mat", 8e-6, channel=i, detrend="none").meta["channel"] for i in (0, 1)]
    assert sorted(names) == ["height", "intensity"]
    with pytest.raises(SurfaceFileError, match="no channel 'depth'"):
        load_surface(tmp_path / "two.mat", 8e-6, channel="depth", detrend="none")


def test_cli_runs_a_gwy_file_without_length(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness import cli
    from contactbench.harness import load_table

    path = write_every_format(tmp_path, round_trip_surface())["gwy"]
    out = tmp_path / "run"
    rc = cli.main(["run", "paper-sweep", "--surface", str(path), "--steps", "2", "--solvers", "nnls",
                   "--reference", "none", "--no-progress", "--no-warmup", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    table = load_table(out)
    assert len(table) == 2 and set(table["solver"]) == {"nnls"}
    rc = cli.main(["run", "paper-sweep", "--surface", str(path), "--length", "1e-3", "--steps", "2",
                   "--solvers", "nnls", "--out", str(tmp_path / "bad")])
    assert rc == 2 and "disagrees" in capsys.readouterr().err


@pytest.mark.parametrize("what", ["constant", "plane", "tiny"])
def test_a_map_with_no_relief_to_solve_on_is_refused(tmp_path: Path, what: str) -> None:
    """A constant map, an exact plane (flat once its tilt is removed: round-off is left) and
    heights so small their slopes underflow: refused naming the file, not solved on noise."""
    yy, xx = np.mgrid[0:16, 0:16].astype(float)
    z = {"constant": np.full((16, 16), 1e-6), "plane": 1e-6 + 3e-8 * xx - 2e-8 * yy,
         "tiny": 1e-300 * random_map((16, 16), seed=2) / 1e-6}[what]
    np.save(tmp_path / f"{what}.npy", z)
    with pytest.raises(SurfaceFileError, match="flat") as err, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tilt warning of the plane
        load_surface(tmp_path / f"{what}.npy", length=16e-6)
    assert f"{what}.npy" in str(err.value)
    rough = 1e-6 + 3e-8 * xx + 1e-12 * random_map((16, 16), seed=3) / 1e-6  # a pm of roughness on a um offset: kept
    np.save(tmp_path / "rough.npy", rough)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert np.ptp(load_surface(tmp_path / "rough.npy", length=16e-6).heights) > 0


def test_a_slope_that_overflows_reads_inf_without_a_warning() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Surface(1e300 * random_map((8, 8)) / 1e-6, 1e-9).rms_slope() == np.inf


@pytest.mark.parametrize("spacing", [float("nan"), -1.0, 0.0, (1e-6, float("inf"))])
def test_the_writer_refuses_a_spacing_its_readers_would(tmp_path: Path, spacing: object) -> None:
    from contactbench.problems.io import write_topography

    with pytest.raises(ProblemInputError, match="spacing"):
        write_topography(tmp_path / "w.nc", random_map((8, 8)), spacing, "netcdf")  # type: ignore[arg-type]
    assert not (tmp_path / "w.nc").exists()
