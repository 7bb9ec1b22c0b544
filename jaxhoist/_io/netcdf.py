"""A minimal writer of classic netCDF files (the 64-bit-offset format, CDF-2), with numpy only.

netCDF is the open, self-describing array format that xarray, NCO, ncview, Panoply, MATLAB, R and most
scientific tools read; writing it here keeps netCDF4/h5py/xarray out of jaxhoist's dependencies. Only
what scan results need: fixed-size dimensions (no record dimension), variables of type double, float, int
or char, and attributes (text, numbers). The layout follows the format specification ("The NetCDF Classic
Format", Unidata): a header of dimensions, global attributes and variables, then every variable's values,
big-endian, each padded to a multiple of 4 bytes.

    write_netcdf("scan.nc", {"member": 3},
                 [("mu", ("member",), np.array([0.1, 0.2, 0.3]), {"units": "1"})], {"title": "demo"})
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

_NC_DIMENSION, _NC_VARIABLE, _NC_ATTRIBUTE = 0x0A, 0x0B, 0x0C
_NC_CHAR, _NC_INT, _NC_FLOAT, _NC_DOUBLE = 2, 4, 5, 6
_DTYPES = {_NC_CHAR: ">S1", _NC_INT: ">i4", _NC_FLOAT: ">f4", _NC_DOUBLE: ">f8"}
_NAME_OK = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.@+-")


def nc_name(text: str) -> str:
    """`text` as a valid classic netCDF name: other characters become '_', and a leading digit or
    punctuation gets a '_' in front (e.g. "load.mass_centre[0]" -> "load.mass_centre_0_")."""
    s = "".join(c if c in _NAME_OK else "_" for c in text)
    return s if s and (s[0].isalpha() or s[0] == "_") else "_" + s


def nc_variable(name: str, dims, values, attrs: Mapping, nc_dims: dict, coordinates: str = "") -> tuple:
    """One variable of a layout (`name`, `dims`, `values`, `attrs`) as `write_netcdf` takes it: names
    netCDF does not allow become '_' (the original kept in the attribute `path`), `coordinates` (if any)
    becomes the CF attribute of that name, and text labels (a list of str) become an (n, strlen) character
    array with a dimension `<dim>_strlen` of its own, added to `nc_dims`.

    **Returns** `(name, dims, values, attrs)` in netCDF names.
    """
    a = {**attrs, "path": name} if nc_name(name) != name else dict(attrs)
    if coordinates:
        a["coordinates"] = coordinates
    dd = tuple(nc_name(x) for x in dims)
    if isinstance(values, list):  # text labels -> (n, strlen) characters
        width = max(1, *(len(x.encode("utf-8")) for x in values))
        nc_dims[f"{dd[0]}_strlen"] = width
        chars = np.array([list(x.encode("utf-8").ljust(width, b"\0")) for x in values], dtype=np.uint8)
        values, dd = chars.view("S1").reshape(len(values), width), (*dd, f"{dd[0]}_strlen")
        a["_Encoding"] = "utf-8"  # read back as text, not bytes
    return nc_name(name), dd, np.asarray(values), a


def _pad(b: bytes) -> bytes:
    return b + b"\0" * (-len(b) % 4)


def _int(v: int) -> bytes:
    return struct.pack(">i", v)


def _name(s: str) -> bytes:
    raw = s.encode("utf-8")
    return _int(len(raw)) + _pad(raw)


def _nc_type(a: np.ndarray) -> int:
    if a.dtype.kind == "S":
        return _NC_CHAR
    if a.dtype.kind in "biu":
        if a.size and (a.min() < -(2**31) or a.max() >= 2**31):
            raise ValueError("netCDF classic has no 64-bit integers; the values do not fit in int32")
        return _NC_INT
    if a.dtype == np.float32:
        return _NC_FLOAT
    if a.dtype.kind == "f":
        return _NC_DOUBLE
    raise TypeError(f"no classic netCDF type for dtype {a.dtype}")


def _values(a: np.ndarray, t: int) -> bytes:
    if t == _NC_CHAR:
        if a.dtype.itemsize != 1:
            raise ValueError(f"text arrays must hold single characters (dtype S1), got {a.dtype}")
        return a.tobytes()
    return np.ascontiguousarray(a, dtype=_DTYPES[t]).tobytes()


def _attribute(name: str, value) -> bytes:
    if isinstance(value, str):
        raw = value.encode("utf-8")
        return _name(name) + _int(_NC_CHAR) + _int(len(raw)) + _pad(raw)
    a = np.atleast_1d(np.asarray(value))
    if a.dtype.kind == "b":
        a = a.astype(np.int32)
    t = _nc_type(a)
    return _name(name) + _int(t) + _int(a.size) + _pad(_values(a, t))


def _attributes(attrs: Mapping[str, object]) -> bytes:
    if not attrs:
        return b"\0" * 8  # ABSENT
    return _int(_NC_ATTRIBUTE) + _int(len(attrs)) + b"".join(_attribute(k, v) for k, v in attrs.items())


def write_netcdf(
    path: str | Path,
    dims: Mapping[str, int],
    variables: Sequence[tuple[str, tuple[str, ...], np.ndarray, Mapping[str, object]]],
    attrs: Mapping[str, object] | None = None,
) -> Path:
    """Write a classic (64-bit offset) netCDF file.

    - `dims`: dimension name -> length (all fixed; names must be valid, see `nc_name`).
    - `variables`: (name, dimension names, array of that shape, attributes). Arrays of float64/float32,
      integers that fit in int32, booleans (written as int) or single characters (dtype "S1", for text).
    - `attrs`: global attributes (str, numbers or sequences of numbers).
    """
    for d, n in dims.items():
        if nc_name(d) != d or int(n) < 1:
            raise ValueError(f"dimension {d!r} of length {n}: names as nc_name gives, lengths >= 1")
    names = [v[0] for v in variables]
    if len(set(names)) != len(names) or any(nc_name(x) != x for x in names):
        raise ValueError(f"variable names must be distinct valid netCDF names, got {names}")
    dim_ids = {d: i for i, d in enumerate(dims)}
    prepared = []
    for name, vdims, arr, vattrs in variables:
        a = np.asarray(arr)
        if a.dtype.kind == "b":
            a = a.astype(np.int32)
        shape = tuple(dims[d] for d in vdims)
        if a.shape != shape:
            raise ValueError(f"variable {name!r}: shape {a.shape} does not match its dimensions {shape}")
        t = _nc_type(a)
        data = _values(a, t)
        prepared.append((name, vdims, t, data, vattrs))

    dim_list = (
        _int(_NC_DIMENSION) + _int(len(dims)) + b"".join(_name(d) + _int(int(n)) for d, n in dims.items())
        if dims
        else b"\0" * 8
    )
    head = b"CDF\x02" + _int(0) + dim_list + _attributes(attrs or {})

    def var_list(begins):
        if not prepared:
            return b"\0" * 8
        out = _int(_NC_VARIABLE) + _int(len(prepared))
        for (name, vdims, t, data, vattrs), begin in zip(prepared, begins, strict=True):
            vsize = len(_pad(data))
            out += _name(name) + _int(len(vdims)) + b"".join(_int(dim_ids[d]) for d in vdims)
            out += _attributes(vattrs) + _int(t) + struct.pack(">I", min(vsize, 2**32 - 1))  # 2^32-1: larger
            out += struct.pack(">q", begin)
        return out

    start = len(head) + len(var_list([0] * len(prepared)))  # the begins have a fixed width
    begins, offset = [], start
    for *_, data, _a in prepared:
        begins.append(offset)
        offset += len(_pad(data))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(head + var_list(begins))
        for *_, data, _a in prepared:
            f.write(_pad(data))
    tmp.replace(path)
    return path
