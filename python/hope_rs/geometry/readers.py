"""Strict parsers of OFF, OBJ, PLY and STL, and binary glTF through trimesh: bytes in,
(vertices, faces) arrays out.

A file is read whole and its counts must agree with its body; a problem at one line raises
:class:`LineError` (the caller names the file). Polygons are fan-triangulated.
"""

from __future__ import annotations

import re
import struct

import numpy as np

__all__ = [
    "READERS",
    "LineError",
    "fan",
    "one_line",
    "read_glb",
    "read_obj",
    "read_off",
    "read_ply",
    "read_stl",
]


class LineError(ValueError):
    """A problem at one line of a text file."""

    def __init__(self, line: int, message: str):
        super().__init__(f"line {line}: {message}")
        self.line, self.message = line, message


def one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def _show(tokens) -> str:
    """A short printable rendering of a line's tokens for an error message."""
    s = " ".join(tokens)
    return repr(s if len(s) <= 40 else s[:37] + "...")


#: The UTF-8 byte-order mark some editors put at the start of a text file.
BOM = b"\xef\xbb\xbf"


def without_bom(data: bytes) -> bytes:
    """``data`` without a leading UTF-8 byte-order mark."""
    return data[len(BOM) :] if data.startswith(BOM) else data


def _text(data: bytes) -> str:
    data = without_bom(data)
    nul = data.find(b"\x00")
    if nul >= 0:
        raise ValueError(f"binary data in a text format (a NUL byte at offset {nul})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        # Numbers are ASCII: a comment in another 8-bit encoding should not stop the reader.
        return data.decode("latin-1")


def _lines(
    data: bytes, comment: str = "#", *, continued: bool = False
) -> list[tuple[int, list[str]]]:
    """The non-empty lines as (1-based line number, tokens), comments removed. ``continued``:
    a line ending in a backslash (outside its comment) goes on on the next line, as OBJ's long
    statements do; the statement takes its first line's number."""
    out = []
    text = _text(data)
    if "\r" in text:  # Windows (CR LF) and classic Mac (CR alone) line ends
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    held: list[str] = []
    first = 0
    for no, ln in enumerate(text.split("\n"), 1):
        if comment in ln:
            ln = ln.split(comment, 1)[0]
        if continued:
            ln = ln.rstrip()
            if not held:
                first = no
            if ln.endswith("\\"):
                held.append(ln[:-1])
                continue
            if held:
                ln, held = " ".join([*held, ln]), []
        tok = ln.split()
        if tok:
            out.append((first if continued else no, tok))
    if held:
        tok = " ".join(held).split()
        if tok:
            out.append((first, tok))
    return out


def _float(s: str, line: int, what: str) -> float:
    try:
        if "_" in s:  # float() reads "1_0" as 10: Python's digit grouping, not a file's
            raise ValueError(s)
        x = float(s)
    except ValueError:
        raise LineError(line, f"expected a number for {what}, got {_show([s])}") from None
    if not np.isfinite(x):
        raise LineError(line, f"{what} is {s} (NaN or infinite coordinates are not allowed)")
    return x


def _number(s: str, line: int) -> float:
    try:
        if "_" in s:
            raise ValueError(s)
        return float(s)
    except ValueError:
        raise LineError(line, f"expected a number, got {_show([s])}") from None


def _int(s: str, line: int, what: str) -> int:
    try:
        return int(s)
    except ValueError:
        raise LineError(line, f"expected an integer for {what}, got {_show([s])}") from None


# --- OFF -----------------------------------------------------------------------------------

_OFF_KEYWORD = re.compile(r"(ST)?(C)?(N)?(4)?(N)?OFF", re.IGNORECASE)


def read_off(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    lines = _lines(data)
    if not lines:
        raise ValueError("the file is empty")
    no, tok = lines[0]
    kw = _OFF_KEYWORD.fullmatch(tok[0])
    if kw is None:
        raise ValueError(f"not an OFF file (the first line must be 'OFF', got {_show(tok)})")
    st, colour, normal, four, n_dim = kw.groups()
    if four or n_dim:
        raise LineError(no, f"{tok[0]} (4-D or n-D vertices) is not supported")
    if len(tok) > 1 and tok[1].upper() == "BINARY":
        raise LineError(no, "binary OFF is not supported; save the mesh as ASCII OFF or PLY")
    if len(tok) > 1:
        head_no, head, body = no, tok[1:], lines[1:]
    elif len(lines) > 1:
        (head_no, head), body = lines[1], lines[2:]
    else:
        raise LineError(no, "the header has no vertex and face counts ('OFF' then 'V F E')")
    if len(head) not in (2, 3):
        raise LineError(head_no, f"expected the counts 'vertices faces [edges]', got {_show(head)}")
    nv, nf = (_int(x, head_no, "a count") for x in head[:2])
    if nv < 0 or nf < 0:
        raise LineError(head_no, f"negative counts: {nv} vertices, {nf} faces")
    n_body = len(body)
    if n_body < nv + nf:
        end = body[-1][0] if body else head_no
        raise LineError(
            end,
            f"the file is shorter than its OFF header (line {head_no}) says: it promises {nv} "
            f"vertices and {nf} faces ({nv + nf} lines), the file ends after {n_body} of them",
        )
    if n_body > nv + nf:
        raise LineError(
            body[nv + nf][0],
            f"more lines than the {nv} vertices and {nf} faces the OFF header (line {head_no}) "
            "promises: the counts must match the body",
        )
    extra = {0} if not st else {0, 2}
    if normal:
        extra = {e + 3 for e in extra}
    if colour:
        extra = {e + c for e in extra for c in (0, 1, 3, 4)}
    allowed = sorted(3 + e for e in extra)
    v = _off_vertices(body[:nv], allowed)
    f = _off_faces(body[nv:], nv)
    return v, f


def _off_vertices(rows, allowed: list[int]) -> np.ndarray:
    n = len(rows)
    if all(len(t) == 3 and "_" not in "".join(t) for _, t in rows):
        try:
            v = np.array([t for _, t in rows], dtype=np.float64).reshape(n, 3)
            if np.all(np.isfinite(v)):
                return v
        except ValueError:
            pass
    v = np.empty((n, 3))
    for i, (no, t) in enumerate(rows):
        if len(t) not in allowed:
            want = " or ".join(map(str, allowed))
            raise LineError(no, f"expected {want} coordinates, got {len(t)}")
        v[i] = [_float(x, no, "a coordinate") for x in t[:3]]
        for x in t[3:]:
            _float(x, no, "a colour, normal or texture value")
    return v


def _off_faces(rows, nv: int) -> np.ndarray:
    # Fast path for the usual all-triangle file; anything unusual goes line by line below.
    if rows and all(len(t) == 4 and t[0] == "3" for _, t in rows):
        try:
            f = np.array([t[1:] for _, t in rows]).astype(np.int64)
        except (ValueError, OverflowError):
            f = None
        if f is not None and f.min() >= 0 and f.max() < nv:
            return f
    tris: list[list[int]] = []
    for no, t in rows:
        k = _int(t[0], no, "the corner count of a face")
        if k < 3:
            raise LineError(no, f"a face needs at least 3 corners, got {k}")
        if len(t) - 1 - k not in (0, 1, 3, 4):
            raise LineError(
                no, f"a face of {k} corners needs {k} vertex indices, got {len(t) - 1} numbers"
            )
        idx = [_int(x, no, "a vertex index") for x in t[1 : 1 + k]]
        bad = [i for i in idx if not 0 <= i < nv]
        if bad:
            if bad[0] < 0:
                raise LineError(no, f"negative vertex index {bad[0]}; OFF indices are 0-based")
            raise LineError(
                no, f"vertex index {bad[0]} is out of range: there are only {nv} vertices (0-based)"
            )
        for x in t[1 + k :]:
            _float(x, no, "a face colour")
        tris.extend([idx[0], idx[i], idx[i + 1]] for i in range(1, k - 1))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


# --- OBJ -----------------------------------------------------------------------------------

_OBJ_IGNORED = frozenset(
    [
        "vt",
        "vn",
        "vp",
        "l",
        "p",
        "g",
        "o",
        "s",
        "mtllib",
        "usemtl",
        "usemap",
        "maplib",
        "cstype",
        "deg",
        "bmat",
        "step",
        "curv",
        "curv2",
        "surf",
        "parm",
        "trim",
        "hole",
        "scrv",
        "sp",
        "end",
        "con",
        "mg",
        "bevel",
        "c_interp",
        "d_interp",
        "lod",
        "shadow_obj",
        "trace_obj",
        "ctech",
        "stech",
        "call",
        "csh",
    ]
)


def read_obj(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    verts: list[list[float]] = []
    tris: list[list[int]] = []
    tri_line: list[int] = []
    for no, t in _lines(data, continued=True):
        key = t[0]
        if key == "v":
            if len(t) not in (4, 5, 7, 8):
                raise LineError(no, f"expected 3 coordinates after 'v', got {len(t) - 1} numbers")
            verts.append([_float(x, no, "a coordinate") for x in t[1:4]])
            for x in t[4:]:
                _float(x, no, "a vertex weight or colour")
        elif key == "f":
            if len(t) < 4:
                raise LineError(no, f"a face needs at least 3 corners, got {len(t) - 1}")
            idx = []
            for c in t[1:]:
                i = _int(c.split("/", 1)[0], no, "a vertex index")
                if i == 0:
                    raise LineError(no, "vertex index 0: OBJ indices start at 1")
                if abs(i) > 2**62:
                    raise LineError(no, f"vertex index {i} is out of range")
                i = i - 1 if i > 0 else len(verts) + i
                if i < 0:
                    raise LineError(no, f"relative index {c} points before the first vertex")
                idx.append(i)
            tris.extend([idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1))
            tri_line.extend([no] * (len(idx) - 2))
        elif key not in _OBJ_IGNORED:
            raise LineError(no, f"unknown OBJ statement {_show([key])}")
    f = np.array(tris, dtype=np.int64).reshape(-1, 3)
    if f.size and f.max() >= len(verts):
        row = int(np.flatnonzero(f.max(axis=1) >= len(verts))[0])
        raise LineError(
            tri_line[row],
            f"vertex index {int(f[row].max()) + 1} is out of range: the file has "
            f"{len(verts)} vertices",
        )
    return np.array(verts, dtype=np.float64).reshape(-1, 3), f


# --- PLY -----------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def read_ply(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    data = without_bom(data)
    end = re.search(rb"end_header[ \t]*\r?\n", data)
    if not data.startswith(b"ply") or end is None:
        raise ValueError("not a PLY file (it must start with 'ply' and have an 'end_header')")
    try:
        header = data[: end.start()].decode("ascii")
    except UnicodeDecodeError:
        raise ValueError("the PLY header is not ASCII text") from None
    fmt: str | None = None
    elements: list[list] = []  # [name, count, [(name, type) or (name, count, item)]]
    for no, line in enumerate(header.split("\n")[1:], 2):
        t = line.split()
        if not t or t[0] in ("comment", "obj_info"):
            continue
        if t[0] == "format" and len(t) == 3:
            if t[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise LineError(no, f"unknown PLY format {_show([t[1]])}")
            fmt = t[1]
        elif t[0] == "element" and len(t) == 3:
            count = _int(t[2], no, "the element count")
            if count < 0:
                raise LineError(no, f"negative element count {count}")
            if any(e[0] == t[1] for e in elements):
                raise LineError(no, f"a second element {_show([t[1]])}; each is declared once")
            elements.append([t[1], count, []])
        elif t[0] == "property" and elements and any(p[0] == t[-1] for p in elements[-1][2]):
            raise LineError(no, f"a second property {_show([t[-1]])} of {_show([elements[-1][0]])}")
        elif t[0] == "property" and elements and len(t) == 3 and t[1] in _PLY_TYPES:
            elements[-1][2].append((t[2], _PLY_TYPES[t[1]]))
        elif (
            t[0] == "property" and elements and len(t) == 5 and t[1] == "list"
            and t[2] in _PLY_TYPES and t[3] in _PLY_TYPES and _PLY_TYPES[t[2]][0] in "iu"
        ):  # fmt: skip
            if t[4] in ("vertex_indices", "vertex_index") and _PLY_TYPES[t[3]][0] not in "iu":
                raise LineError(no, f"face indices must be integers, not {t[3]}")
            elements[-1][2].append((t[4], _PLY_TYPES[t[2]], _PLY_TYPES[t[3]]))
        else:
            raise LineError(no, f"unexpected PLY header line {_show(t)}")
    if fmt is None:
        raise ValueError("the PLY header has no 'format' line")
    body = data[end.end() :]
    if fmt == "ascii":
        values = _ply_ascii(body, elements, header.count("\n") + 2)
    else:
        values = _ply_binary(body, elements, ">" if fmt.endswith("big_endian") else "<")
    vert = values.get("vertex")
    if vert is None or not all(k in vert for k in "xyz"):
        raise ValueError("the PLY file has no 'vertex' element with x, y and z")
    if any(np.ndim(vert[k]) != 1 for k in "xyz"):
        raise ValueError("the PLY vertex coordinates x, y and z must be numbers, not lists")
    v = np.stack([np.asarray(vert[k], dtype=np.float64) for k in "xyz"], axis=1)
    faces = values.get("face", {})
    lists = faces.get("vertex_indices", faces.get("vertex_index"))
    if lists is None or (len(lists) and np.ndim(lists[0]) == 0):  # absent, or not a list
        raise ValueError("the PLY file has no 'face' element with a vertex_indices list")
    return v, _fan(lists)


def fan(polygons: np.ndarray) -> np.ndarray:
    """An (M, k) array of polygons fan-triangulated (corner 0 with each pair of consecutive
    others), each polygon's triangles in its place, in the array's dtype."""
    k = polygons.shape[1]
    tris = [
        np.stack([polygons[:, 0], polygons[:, i], polygons[:, i + 1]], 1) for i in range(1, k - 1)
    ]
    return np.stack(tris, 1).reshape(-1, 3)


def _fan(lists) -> np.ndarray:
    """Fan-triangulate a list of polygons (an (M, k) array or a list of index lists)."""
    if isinstance(lists, np.ndarray) and lists.ndim == 2 and lists.shape[1] >= 3:
        return fan(lists).astype(np.int64)
    tris: list[list[int]] = []
    for poly in lists:
        poly = [int(i) for i in poly]
        if len(poly) < 3:
            raise ValueError(f"a face has {len(poly)} corners; faces need at least 3")
        tris.extend([poly[0], poly[i], poly[i + 1]] for i in range(1, len(poly) - 1))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _ply_ascii(body: bytes, elements, first_line: int) -> dict:
    lines = _lines(body, comment="\x00")
    need = sum(e[1] for e in elements)
    if len(lines) != need:
        what = "shorter" if len(lines) < need else "longer"
        raise ValueError(
            f"the PLY body is {what} than its header says: {need} element lines promised, "
            f"{len(lines)} found"
        )
    out, at = {}, 0
    for name, count, props in elements:
        cols: dict = {p[0]: [] for p in props}
        for no, t in lines[at : at + count]:
            no += first_line - 1
            k = 0
            for p in props:
                if len(p) == 2:
                    if k >= len(t):
                        raise LineError(no, f"too few values for element {name!r}")
                    x = t[k]
                    cols[p[0]].append(
                        _float(x, no, p[0]) if p[0] in ("x", "y", "z") else _number(x, no)
                    )
                    k += 1
                else:
                    n = _int(t[k], no, "a list length") if k < len(t) else -1
                    if n < 0 or k + 1 + n > len(t):
                        raise LineError(no, f"malformed list in element {name!r}")
                    entries = t[k + 1 : k + 1 + n]
                    if p[2][0] == "f":  # a float list (texture coordinates): read, not used
                        cols[p[0]].append([_number(x, no) for x in entries])
                    else:
                        cols[p[0]].append([_int(x, no, "a list entry") for x in entries])
                    k += 1 + n
            if k != len(t):
                raise LineError(no, f"{len(t) - k} values more than element {name!r} has")
        out[name] = cols
        at += count
    return out


def _ply_binary(body: bytes, elements, endian: str) -> dict:
    out, off = {}, 0
    for name, count, props in elements:
        # At least one byte per item and per scalar: bounds a huge count without allocating.
        least = sum(np.dtype(p[1]).itemsize for p in props)
        if count * least > len(body) - off:
            raise ValueError(
                f"the PLY body is shorter than its header says ({count} {name!r} elements)"
            )
        if all(len(p) == 2 for p in props):
            dt = np.dtype([(p[0], endian + p[1]) for p in props])
            arr = np.frombuffer(body, dtype=dt, count=count, offset=off)
            out[name] = {p[0]: arr[p[0]] for p in props}
            off += count * dt.itemsize
            continue
        out[name], off = _ply_binary_lists(body, off, count, props, endian, name)
    if off != len(body) and body[off:].strip():
        raise ValueError(f"{len(body) - off} bytes after the last element the header declares")
    return out


def _scalar(body: bytes, dtype: str, off: int):
    size = np.dtype(dtype).itemsize
    if off + size > len(body):
        raise ValueError("the PLY body ends inside an element")
    return np.frombuffer(body, dtype, 1, off)[0].item(), off + size


def _ply_binary_lists(body, off, count, props, endian, name):
    # Fast path: every list as long as the first one (triangle meshes).
    k, pos = None, off
    if count:
        for p in props:
            if len(p) == 3:
                k = _scalar(body, endian + p[1], pos)[0] if pos < len(body) else -1
                break
            pos += np.dtype(p[1]).itemsize
    if k is not None and 0 <= k <= 64:
        fields: list[tuple] = []
        for p in props:
            if len(p) == 2:
                fields.append((p[0], endian + p[1]))
            else:
                fields += [(p[0] + "#n", endian + p[1]), (p[0], endian + p[2], (k,))]
        dt = np.dtype(fields)
        if count * dt.itemsize <= len(body) - off:
            arr = np.frombuffer(body, dtype=dt, count=count, offset=off)
            if all(np.all(arr[p[0] + "#n"] == k) for p in props if len(p) == 3):
                return {p[0]: arr[p[0]] for p in props}, off + count * dt.itemsize
    # Lists of several lengths: item by item (each consumes at least one byte).
    cols: dict = {p[0]: [] for p in props}
    for _ in range(count):
        for p in props:
            if len(p) == 2:
                x, off = _scalar(body, endian + p[1], off)
                cols[p[0]].append(x)
            else:
                n, off = _scalar(body, endian + p[1], off)
                size = np.dtype(p[2]).itemsize
                if n < 0 or off + n * size > len(body):
                    raise ValueError(f"the PLY body ends inside element {name!r}")
                cols[p[0]].append(np.frombuffer(body, endian + p[2], n, off).tolist())
                off += n * size
    return cols, off


# --- STL -----------------------------------------------------------------------------------


#: ASCII STL's nesting: each keyword's depth before it and after it (0 outside a solid, 1 in
#: a solid, 2 in a facet).
_STL_NESTING = {"solid": (0, 1), "facet": (1, 2), "endfacet": (2, 1), "endsolid": (1, 0)}
_STL_DEPTHS = ("outside a solid", "inside a solid", "inside a facet")


def read_stl(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    if len(data) >= 84:
        n = struct.unpack_from("<I", data, 80)[0]
        if len(data) == 84 + 50 * n:
            dt = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            tri = np.frombuffer(data, dtype=dt, count=n, offset=84)["v"].astype(np.float64)
            return tri.reshape(-1, 3), np.arange(3 * n, dtype=np.int64).reshape(-1, 3)
    if not data.lstrip().lower().startswith(b"solid"):
        raise ValueError(
            "neither binary STL (its size does not match the triangle count in its header) "
            "nor ASCII STL (it does not start with 'solid')"
        )
    verts = []
    # How deep the parser is (0 outside a solid, 1 in a solid, 2 in a facet): a file cut short
    # ends inside one of them, and is refused rather than read as the facets before the cut.
    depth = 0
    for no, t in _lines(data, comment="\x00"):
        key = t[0].lower()
        if key == "vertex":
            if len(t) != 4:
                raise LineError(no, f"expected 3 coordinates after 'vertex', got {len(t) - 1}")
            verts.append([_float(x, no, "a coordinate") for x in t[1:]])
        elif key == "endloop":
            if len(verts) % 3:
                raise LineError(no, "a facet needs exactly 3 vertices")
        elif key in _STL_NESTING:
            need, depth_after = _STL_NESTING[key]
            if depth != need:
                raise LineError(no, f"{key!r} {_STL_DEPTHS[depth]}")
            depth = depth_after
        elif key != "outer":
            raise LineError(no, f"unexpected ASCII STL line {_show(t)}")
    if len(verts) % 3 or depth == 2:
        raise ValueError("the file ends inside a facet (cut short?)")
    if depth == 1:
        raise ValueError("the file ends before 'endsolid' (cut short?)")
    v = np.array(verts, dtype=np.float64).reshape(-1, 3)
    return v, np.arange(v.shape[0], dtype=np.int64).reshape(-1, 3)


def read_glb(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Binary glTF (``.glb``, as scanning apps and asset stores export) read by trimesh: the
    triangles of every mesh in the scene, placed as the scene places them, one mesh after
    another in trimesh's order, each mesh's vertices as stored (glTF splits them along
    texture seams; :func:`~hope_rs.match` welds those)."""
    import io

    import trimesh

    if not data.startswith(b"glTF"):
        raise ValueError("not a binary glTF file (it does not start with 'glTF')")
    try:
        scene = trimesh.load(io.BytesIO(data), file_type="glb", force="scene", process=False)
        assert isinstance(scene, trimesh.Scene)  # force="scene"
    except Exception as e:  # trimesh raises many kinds on a damaged file
        raise ValueError(f"trimesh cannot read it: {one_line(e)}") from None
    meshes = [g for g in scene.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
    if not meshes:
        raise ValueError("the scene holds no triangle mesh")
    counts = np.cumsum([0] + [len(m.vertices) for m in meshes])
    v = np.concatenate([np.asarray(m.vertices, dtype=np.float64) for m in meshes])
    f = np.concatenate([np.asarray(m.faces, dtype=np.int64) + c for m, c in zip(meshes, counts)])
    return v, f


#: The parser of each file extension :func:`hope_rs.load_mesh` reads.
READERS = {
    ".off": read_off,
    ".obj": read_obj,
    ".ply": read_ply,
    ".stl": read_stl,
    ".glb": read_glb,
}
