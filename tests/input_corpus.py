"""A fuzz corpus of small mesh files, generated from code: malformed files every reader must
refuse with a one-line error, and odd but valid files it must read.

``BAD``: name -> (extension, bytes, a fragment the error message must contain).
``ODD``: name -> (extension, bytes, vertex count, face count) of files that load.
``MATCH_ERRORS``: files that load but cannot be matched (the error comes from ``match``).
"""

import struct

import numpy as np

TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def off_text(v, f, head="OFF", counts=None, vertex_suffix="", face_suffix="", newline="\n"):
    counts = f"{len(v)} {len(f)} 0" if counts is None else counts
    lines = [head, counts]
    lines += [f"{x:g} {y:g} {z:g}{vertex_suffix}" for x, y, z in v]
    lines += [f"{len(p)} " + " ".join(map(str, p)) + face_suffix for p in f]
    return (newline.join(lines) + newline).encode()


TET_BODY = off_text(TET_V, TET_F).split(b"\n", 2)[2]  # the 8 body lines


def off(head: str, body: bytes = TET_BODY) -> bytes:
    return (head + "\n").encode() + body


def obj_text(v, f, extra: str = "") -> bytes:
    lines = [f"v {x:g} {y:g} {z:g}" for x, y, z in v]
    lines += ["f " + " ".join(str(i + 1) for i in p) for p in f]
    return ("\n".join(lines) + "\n" + extra).encode()


def ply_ascii(v, f, vertex_count=None) -> bytes:
    n = len(v) if vertex_count is None else vertex_count
    head = (
        f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\n"
        "end_header\n"
    )
    body = "".join(f"{x:g} {y:g} {z:g}\n" for x, y, z in v)
    body += "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in f)
    return (head + body).encode()


def ply_binary(v, f, endian="<", vertex_count=None) -> bytes:
    n = len(v) if vertex_count is None else vertex_count
    name = "binary_little_endian" if endian == "<" else "binary_big_endian"
    head = (
        f"ply\nformat {name} 1.0\ncomment generated\nelement vertex {n}\nproperty double x\n"
        "property double y\nproperty double z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    body = b"".join(struct.pack(endian + "3d", *p) for p in v)
    body += b"".join(struct.pack(f"{endian}B{len(p)}i", len(p), *p) for p in f)
    return head + body


def stl_binary(v, f, count=None) -> bytes:
    out = [b"\0" * 80, struct.pack("<I", len(f) if count is None else count)]
    for p in f:
        out.append(struct.pack("<12fH", 0, 0, 0, *v[p].reshape(-1), 0))
    return b"".join(out)


def stl_ascii(v, f) -> bytes:
    s = ["solid t"]
    for p in f:
        s += ["facet normal 0 0 0", "outer loop"]
        s += [f"vertex {x:g} {y:g} {z:g}" for x, y, z in v[p]]
        s += ["endloop", "endfacet"]
    return ("\n".join(s + ["endsolid t"]) + "\n").encode()


TET_OFF = off_text(TET_V, TET_F)
JUNK = bytes(range(256)) * 4

BAD = {
    # OFF
    "off_empty": ("off", b"", "empty"),
    "off_blank": ("off", b"\n  \n\t\n", "empty"),
    "off_not_off": ("off", b"hello world\n", "not an OFF"),
    "off_header_only": ("off", b"OFF\n", "no vertex and face counts"),
    "off_counts_only": ("off", b"OFF\n4 4 0\n", "shorter"),
    "off_too_few_lines": ("off", off("OFF\n5 4 0"), "shorter"),
    "off_face_read_as_vertex": ("off", off("OFF\n5 3 0"), "line 7: expected 3 coordinates, got 4"),
    "off_surplus_face": ("off", off("OFF\n4 3 0"), "line 10: more lines"),
    "off_trailing_garbage": ("off", TET_OFF + b"garbage here\n", "line 11: more lines"),
    "off_two_coordinates": ("off", TET_OFF.replace(b"1 0 0\n", b"1 0\n", 1), "line 4: expected 3 coordinates, got 2"),
    "off_word_for_number": ("off", TET_OFF.replace(b"1 0 0\n", b"1 zero 0\n", 1), "line 4: expected a number"),
    "off_grouped_digits": ("off", TET_OFF.replace(b"1 0 0\n", b"1_0 0 0\n", 1), "line 4: expected a number"),
    "off_word_for_count": ("off", off("OFF\nfour 4 0"), "line 2: expected an integer"),
    "off_float_count": ("off", off("OFF\n4.0 4 0"), "expected an integer"),
    "off_negative_count": ("off", off("OFF\n-4 4 0"), "negative counts"),
    "off_huge_count": ("off", off("OFF\n1000000000000 4 0"), "shorter"),
    "off_too_many_counts": ("off", off("OFF\n4 4 0 9"), "expected the counts"),
    "off_index_out_of_range": ("off", TET_OFF.replace(b"3 1 2 3\n", b"3 1 2 7\n"), "line 10: vertex index 7 is out of range"),
    "off_negative_index": ("off", TET_OFF.replace(b"3 1 2 3\n", b"3 1 2 -1\n"), "negative"),
    "off_two_corner_face": ("off", TET_OFF.replace(b"3 1 2 3\n", b"2 1 2\n"), "at least 3 corners"),
    "off_corner_count_mismatch": ("off", TET_OFF.replace(b"3 1 2 3\n", b"5 1 2 3\n"), "needs 5 vertex indices"),
    "off_nan": ("off", TET_OFF.replace(b"1 0 0\n", b"1 0 nan\n", 1), "NaN"),
    "off_inf": ("off", TET_OFF.replace(b"1 0 0\n", b"1 0 1e999\n", 1), "infinite"),
    "off_binary_junk": ("off", JUNK, "binary data"),
    "off_binary_variant": ("off", b"OFF BINARY\n4 4 0\n", "binary OFF"),
    "off_4d": ("off", off("4OFF\n4 4 0"), "not supported"),
    "off_vertex_word_suffix": ("off", TET_OFF.replace(b"1 0 0\n", b"1 0 0 foo\n", 1), "got 4"),
    "off_no_faces": ("off", b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no faces"),
    "off_no_vertices": ("off", b"OFF\n0 0 0\n", "no vertices"),
    "off_latin1_number": ("off", TET_OFF.replace(b"1 0 0\n", b"1 0 \xe9\n", 1), "expected a number"),
    # OBJ
    "obj_empty": ("obj", b"", "empty"),
    "obj_garbage_text": ("obj", b"hello world\n", "unknown OBJ statement"),
    "obj_binary_junk": ("obj", JUNK, "binary data"),
    "obj_index_zero": ("obj", obj_text(TET_V, TET_F) + b"f 0 1 2\n", "start at 1"),
    "obj_index_out_of_range": ("obj", obj_text(TET_V, TET_F) + b"f 1 2 9\n", "line 9: vertex index 9 is out of range"),
    "obj_nan": ("obj", b"v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "NaN"),
    "obj_two_coordinates": ("obj", b"v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "line 1: expected 3 coordinates"),
    "obj_two_corner_face": ("obj", obj_text(TET_V, TET_F) + b"f 1 2\n", "at least 3 corners"),
    "obj_no_faces": ("obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    "obj_relative_before_first": ("obj", b"v 0 0 0\nf -1 -2 -3\n", "before the first vertex"),
    "obj_word_index": ("obj", obj_text(TET_V, TET_F) + b"f a b c\n", "expected an integer"),
    "obj_continued_index_out_of_range": ("obj", obj_text(TET_V, TET_F) + b"f 1 \\\n2 \\\n9\n", "line 9: vertex index 9 is out of range"),
    "obj_huge_index": ("obj", obj_text(TET_V, TET_F) + b"f 1 2 99999999999999999999999\n", "out of range"),
    # PLY
    "ply_empty": ("ply", b"", "empty"),
    "ply_garbage_text": ("ply", b"hello world\n", "not a PLY"),
    "ply_binary_junk": ("ply", b"\x00\xff" * 100, "not a PLY"),
    "ply_no_end_header": ("ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", "not a PLY"),
    "ply_unknown_format": ("ply", ply_ascii(TET_V, TET_F).replace(b"ascii", b"utf8"), "unknown PLY format"),
    "ply_float_face_indices": ("ply", ply_ascii(TET_V, TET_F).replace(b"list uchar int", b"list uchar float"), "face indices must be integers"),
    "ply_bad_property": ("ply", ply_ascii(TET_V, TET_F).replace(b"property float z", b"property quux z"), "unexpected PLY header line"),
    "ply_ascii_huge_count": ("ply", ply_ascii(TET_V, TET_F, vertex_count=10**12), "shorter"),
    "ply_binary_huge_count": ("ply", ply_binary(TET_V, TET_F, vertex_count=10**12), "shorter"),
    "ply_binary_truncated": ("ply", ply_binary(TET_V, TET_F)[:-7], "PLY body"),
    "ply_binary_trailing_bytes": ("ply", ply_binary(TET_V, TET_F) + b"\x01\x02\x03", "bytes after"),
    "ply_ascii_too_few_values": ("ply", ply_ascii(TET_V, TET_F).replace(b"1 0 0\n", b"1 0\n", 1), "too few values"),
    "ply_ascii_nan": ("ply", ply_ascii(TET_V, TET_F).replace(b"1 0 0\n", b"1 nan 0\n", 1), "NaN"),
    "ply_index_out_of_range": ("ply", ply_ascii(TET_V, TET_F).replace(b"3 1 2 3\n", b"3 1 2 9\n"), "refer to vertex 9"),
    "ply_no_faces_element": ("ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n", "no 'face' element"),
    "ply_property_twice": ("ply", ply_ascii(TET_V, TET_F).replace(b"property float x\n", b"property float x\nproperty float x\n"), "a second property 'x'"),
    "ply_x_as_a_list": ("ply", ply_ascii(TET_V, TET_F).replace(b"property float x\n", b"property list uchar float x\n").replace(b"\n0 0 0\n", b"\n1 0 0 0\n").replace(b"\n1 0 0\n", b"\n1 1 0 0\n").replace(b"\n0 1 0\n", b"\n1 0 1 0\n").replace(b"\n0 0 1\n", b"\n1 0 0 1\n"), "must be numbers, not lists"),
    "ply_indices_not_a_list": ("ply", ply_ascii(TET_V, TET_F).replace(b"property list uchar int vertex_indices", b"property int vertex_indices").replace(b"3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n", b"0\n1\n2\n3\n"), "no 'face' element with a vertex_indices list"),
    "ply_vertex_element_twice": ("ply", ply_ascii(TET_V, TET_F).replace(b"element face", b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face"), "a second element 'vertex'"),
    "ply_negative_count": ("ply", ply_ascii(TET_V, TET_F).replace(b"element face 4", b"element face -4"), "negative"),
    # STL
    "stl_empty": ("stl", b"", "empty"),
    "stl_garbage_text": ("stl", b"hello world\n", "neither binary STL"),
    "stl_binary_junk": ("stl", JUNK, "neither binary STL"),
    "stl_huge_count": ("stl", stl_binary(TET_V, TET_F, count=10**9), "neither binary STL"),
    "stl_incomplete_facet": ("stl", stl_ascii(TET_V, TET_F).replace(b"vertex 0 0 1\nendloop", b"endloop", 1), "exactly 3 vertices"),
    "stl_nan": ("stl", stl_ascii(TET_V, TET_F).replace(b"vertex 1 0 0", b"vertex 1 nan 0", 1), "NaN"),
    "stl_ascii_cut_after_a_facet": ("stl", stl_ascii(TET_V, TET_F).rsplit(b"endsolid", 1)[0], "ends before 'endsolid'"),
    "stl_ascii_cut_in_a_facet_line": ("stl", stl_ascii(TET_V, TET_F).rsplit(b"endfacet", 1)[0] + b"endfacet\nfacet no", "ends inside a facet"),
    "stl_two_coordinates": ("stl", stl_ascii(TET_V, TET_F).replace(b"vertex 1 0 0", b"vertex 1 0", 1), "expected 3 coordinates"),
    # Unknown formats
    "unknown_extension": ("xyz", TET_OFF, "unknown mesh format '.xyz'; supported: .off, .obj, .ply, .stl"),
    "no_extension": ("", TET_OFF, "unknown mesh format"),
}  # fmt: skip

CUBE_V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
CUBE_QUADS = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
BOOK_V = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1.0]])
BOOK_F = np.array([[0, 1, 2], [0, 1, 3], [1, 0, 4]])

ODD = {
    "off_bom_crlf_comments": (
        "off",
        b"\xef\xbb\xbf# made by hand\r\n" + off_text(TET_V, TET_F, counts="4 4 0 # V F E", newline="\r\n"),
        4, 4,
    ),
    "off_cr_only": ("off", off_text(TET_V, TET_F, newline="\r"), 4, 4),
    "obj_cr_only": ("obj", obj_text(TET_V, TET_F).replace(b"\n", b"\r"), 4, 4),
    "off_counts_on_header_line": ("off", b"OFF 4 4 0\n" + TET_BODY, 4, 4),
    "off_two_counts": ("off", b"OFF\n4 4\n" + TET_BODY, 4, 4),
    "off_coff": ("off", off_text(TET_V, TET_F, head="COFF", vertex_suffix=" 255 0 0 255"), 4, 4),
    "off_noff": ("off", off_text(TET_V, TET_F, head="NOFF", vertex_suffix=" 0 0 1"), 4, 4),
    "off_face_colours": ("off", off_text(TET_V, TET_F, face_suffix=" 255 0 0"), 4, 4),
    "off_lowercase": ("off", off_text(TET_V, TET_F, head="off"), 4, 4),
    "off_quads": ("off", off_text(CUBE_V, CUBE_QUADS), 8, 12),
    "off_duplicate_face": ("off", off_text(TET_V, np.vstack([TET_F, TET_F[:1]])), 4, 5),
    "off_degenerate_face": ("off", off_text(TET_V, np.vstack([TET_F, [[0, 0, 1]]])), 4, 5),
    "off_unreferenced_vertex": ("off", off_text(np.vstack([TET_V, [[5, 5, 5]]]), TET_F), 5, 4),
    "off_single_triangle": ("off", off_text(TET_V[:3], TET_F[:1]), 3, 1),
    "off_two_components": ("off", off_text(np.vstack([TET_V, TET_V + 3]), np.vstack([TET_F, TET_F + 4])), 8, 8),
    "off_non_manifold_edge": ("off", off_text(BOOK_V, BOOK_F), 5, 3),
    "off_inward": ("off", off_text(TET_V, TET_F[:, ::-1]), 4, 4),
    "off_no_final_newline": ("off", TET_OFF.rstrip(b"\n"), 4, 4),
    "obj_with_uv_normals_groups": (
        "obj",
        b"# comment\nmtllib m.mtl\no tet\ng g1\ns off\nusemtl red\n"
        + obj_text(TET_V, []).rstrip(b"\n")
        + b"\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
        + b"f 1/1/1 3/2/1 2/3/1\nf 1//1 2//1 4//1\nf 1/1 4/2 3/3\nf 2 3 4\n",
        4, 4,
    ),
    "obj_relative_indices": ("obj", obj_text(TET_V, []) + b"f -4 -2 -3\nf -4 -3 -1\nf -4 -1 -2\nf -3 -2 -1\n", 4, 4),
    "obj_quads_crlf": ("obj", obj_text(CUBE_V, CUBE_QUADS).replace(b"\n", b"\r\n"), 8, 12),
    # A backslash at a line's end continues the statement (a comment after it does not).
    "obj_line_continuation": (
        "obj",
        b"v 0 0 \\\n0\nv 1 0 0 # x \\\nv 0 1 0\nv 0 0 1\nf 1 3 \\\r\n 2\nf 1 \\\n2 \\\n 4\nf 1 4 3\nf 2 3 4 \\",
        4, 4,
    ),
    "ply_ascii": ("ply", ply_ascii(TET_V, TET_F), 4, 4),
    "ply_binary_little": ("ply", ply_binary(TET_V, TET_F), 4, 4),
    "ply_binary_big": ("ply", ply_binary(TET_V, TET_F, endian=">"), 4, 4),
    "ply_binary_quads": ("ply", ply_binary(CUBE_V, CUBE_QUADS + [[0, 1, 2]]), 8, 13),
    "ply_ascii_float_lists": (
        # Float lists (texture coordinates, as MeshLab writes them) are read and not used.
        "ply",
        b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        b"property float z\nproperty list uchar float uv\nelement face 4\n"
        b"property list uchar int vertex_indices\nproperty list uchar float texcoord\n"
        b"end_header\n0 0 0 0\n1 0 0 2 0.5 0.25\n0 1 0 1 0.5\n0 0 1 2 1 1\n"
        b"3 0 2 1 0\n3 0 1 3 6 0 0 1 0 0 1\n3 0 3 2 1 0.5\n3 1 2 3 2 0.1 0.2\n",
        4, 4,
    ),
    "ply_ascii_quads": ("ply", ply_ascii(CUBE_V, CUBE_QUADS), 8, 12),
    "stl_ascii": ("stl", stl_ascii(TET_V, TET_F), 4, 4),
    "stl_binary": ("stl", stl_binary(TET_V, TET_F), 4, 4),
}  # fmt: skip

MATCH_ERRORS = {
    "off_zero_area": ("off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n", "zero surface area"),
}
