"""Map files: formats by suffix, atomic writes with the usual permissions, checked reads."""

import errno
import os
import stat
import threading

import numpy as np
import pytest
from conftest import unwritable_folder

import hope_rs
from hope_rs.geometry.map_io import (
    atomic_write,
    check_writable_folder,
    read_landmarks,
    read_map,
    write_map,
)

MAP = np.array([3, 0, 2, 2, 1], dtype=np.int64)


@pytest.mark.parametrize("name", ["m.txt", "m.csv", "m", "m.npy", "M.NPY"])
def test_every_written_format_reads_back(tmp_path, name):
    path = tmp_path / name
    write_map(path, MAP)
    got = read_map(path, n=5, n_target=4)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, MAP)
    if name.lower().endswith(".npy"):  # a real NumPy file, not text under a .npy name
        np.testing.assert_array_equal(np.load(path), MAP)
        assert np.load(path).dtype == np.int64
    else:
        assert path.read_text() == "3\n0\n2\n2\n1\n"
    assert hope_rs.read_map is read_map and hope_rs.write_map is write_map


def test_unknown_suffix_and_bad_arrays_write_nothing(tmp_path):
    with pytest.raises(ValueError, match=r"m\.npz'.*unknown suffix '\.npz'.*\.npy"):
        write_map(tmp_path / "m.npz", MAP)
    with pytest.raises(ValueError, match="1-D integer array"):
        write_map(tmp_path / "m.txt", MAP.astype(float))
    with pytest.raises(ValueError, match="1-D integer array"):
        write_map(tmp_path / "m.txt", MAP.reshape(1, -1))
    # What read_map would refuse is not written either.
    with pytest.raises(ValueError, match="indices >= 0, got -1"):
        write_map(tmp_path / "m.txt", np.array([0, -1, 2]))
    with pytest.raises(ValueError, match="fit in int64, got 18446744073709551615"):
        write_map(tmp_path / "m.npy", np.array([0, 2**64 - 1], dtype=np.uint64))
    assert list(tmp_path.iterdir()) == []


def test_a_text_map_named_npy_is_still_read(tmp_path):
    path = tmp_path / "old.npy"  # what `hope-rs match -o x.npy` used to write
    path.write_text("3\n0\n2\n2\n1\n")
    np.testing.assert_array_equal(read_map(path, 5, 4), MAP)


@pytest.mark.parametrize(
    "content, match",
    [
        (b"", "has 0 entries but A has 5"),
        (b"3\n0\n2\n", "has 3 entries but A has 5"),
        (b"\x00\xff\x10garbage", "is not a map file"),
        (b"3\n0\nx\n2\n1\n", "is not a map file"),
        (b"3\n0\n2.5\n2\n1\n", "is not a map file"),
        (b"3\n0\n1_0\n2\n1\n", "is not a map file"),  # int() reads it as 10
        (b"3\n0\n2\n2\n4\n", "holds index 4 but B has 4 vertices"),
        (b"3\n0\n-2\n2\n1\n", "negative index"),
    ],
)
def test_bad_text_maps_get_one_line_errors_naming_the_file(tmp_path, content, match):
    path = tmp_path / "bad.txt"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=match) as err:
        read_map(path, n=5, n_target=4)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "content, message",
    [
        (b"1\n2\n3\nabc\n5\n", r"bad\.txt:4: 'abc' is not a vertex index"),
        (b"1 2\n3 4\n", r"bad\.txt:1: '1 2' holds 2 values \(expected one 0-based"),
        (b"0\n1,2\n", r"bad\.txt:2: '1,2' is not a vertex index"),
        (b"0\r\n\r\n-2\r\n", r"bad\.txt:3: negative index -2; indices are 0-based"),
        (b"0\n99999999999999999999\n", r"bad\.txt:2: index '9+' is too large"),
        (b"0\n1\n\xff\n", r"bad\.txt:3: byte 0xff is not text"),
        (b"0\r1\r\xff\r", r"bad\.txt:3: byte 0xff is not text"),  # CR line ends
        (b"# header\n0\n", r"bad\.txt:1: '# header' is not a vertex index"),
        (b"0\n\n1\n3\n2\n", r"bad\.txt:4: the map holds index 3 but B has 3 vertices"),
    ],
)
def test_a_bad_text_map_line_is_named_by_its_number(tmp_path, content, message):
    path = tmp_path / "bad.txt"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as err:
        read_map(path, n_target=3)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_text_maps_skip_blank_lines_and_take_signs_and_line_ends_of_any_kind(tmp_path):
    path = tmp_path / "m.txt"
    path.write_bytes(b"\xef\xbb\xbf3\r\n\n +0 \r2\t\n0002\n1")
    np.testing.assert_array_equal(read_map(path, 5, 4), [3, 0, 2, 2, 1])
    path.write_bytes(b"00000000000000000000003\n0\n2\n2\n1\n")  # leading zeros are no size
    np.testing.assert_array_equal(read_map(path, 5, 4), MAP)


def test_bad_npy_maps(tmp_path):
    path = tmp_path / "m.npy"
    np.save(path, MAP)
    path.write_bytes(path.read_bytes()[:-8])  # cut short
    with pytest.raises(ValueError, match="damaged NumPy file"):
        read_map(path, 5)
    np.save(path, MAP.astype(float))
    with pytest.raises(ValueError, match="must hold integers"):
        read_map(path, 5)
    np.save(path, MAP.reshape(5, 1))
    with pytest.raises(ValueError, match="1-D array"):
        read_map(path, 5)
    np.save(path, np.array([0, 1, 2, 3, 2**63 + 5], dtype=np.uint64))
    with pytest.raises(ValueError, match=f"holds index {2**63 + 5}, too large"):
        read_map(path, 5)
    np.save(path, np.array([object()] * 5), allow_pickle=True)
    with pytest.raises(ValueError, match="damaged NumPy file"):  # pickles are refused
        read_map(path, 5)
    with pytest.raises(FileNotFoundError, match="no such map file"):
        read_map(tmp_path / "missing.txt")


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_files_get_the_usual_permissions(tmp_path, mask):
    old = os.umask(mask)
    try:
        for name in ("m.txt", "m.npy"):
            write_map(tmp_path / name, MAP)
            assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~mask
    finally:
        os.umask(old)


@pytest.mark.parametrize("where", ["file", "device"])
def test_a_write_the_disk_refuses_names_the_file(tmp_path, where):
    def full(fh):
        raise OSError(errno.ENOSPC, "No space left on device")

    path = tmp_path / "m.txt" if where == "file" else "/dev/null"
    with pytest.raises(OSError, match=rf"No space left on device: '{path}'") as info:
        atomic_write(path, full)
    assert info.value.strerror == "No space left on device"  # messages built on it stay short
    assert list(tmp_path.iterdir()) == []


def test_a_short_write_without_an_error_number_names_the_file(tmp_path):
    # NumPy reports a write cut short by a full disk or a file size limit without errno.
    def short(fh):
        raise OSError("4999 requested and 1008 written")

    path = tmp_path / "m.npy"
    with pytest.raises(OSError, match=rf"cannot write '{path}': 4999 requested and 1008 written"):
        atomic_write(path, short)
    assert list(tmp_path.iterdir()) == []


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "m.txt"
    write_map(path, MAP)

    def half_then_fail(fh):
        fh.write(b"9\n9\n")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(path, half_then_fail)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.txt"]
    np.testing.assert_array_equal(read_map(path, 5, 4), MAP)


def test_check_writable_folder(tmp_path):
    with pytest.raises(ValueError, match=r"output folder '.*missing' does not exist"):
        check_writable_folder(tmp_path / "missing")
    assert check_writable_folder(tmp_path / "new" / "sub", create=True).is_dir()
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="exists and is not a folder"):
        check_writable_folder(tmp_path / "file", create=True)
    ro = unwritable_folder(tmp_path)
    with pytest.raises(ValueError, match=f"cannot write to output folder '{ro}'"):
        check_writable_folder(ro)
    assert list((tmp_path / "new" / "sub").iterdir()) == []  # the probe is removed


def test_a_link_is_followed_and_kept(tmp_path):
    target = tmp_path / "real.txt"
    target.write_text("old\n")
    link = tmp_path / "link.txt"
    link.symlink_to(target.name)
    write_map(link, MAP)
    assert link.is_symlink()  # the link stays a link ...
    np.testing.assert_array_equal(read_map(target), MAP)  # ... and its target holds the map
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.txt", "real.txt"]


def test_a_fifo_is_written_in_place_not_replaced(tmp_path):
    fifo = tmp_path / "map.txt"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    write_map(fifo, MAP)
    reader.join(timeout=30)
    assert got == ["3\n0\n2\n2\n1\n"]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)  # still a FIFO, not a plain file


def test_a_device_is_written_in_place(tmp_path):
    # /dev/null is a device every system has: replacing it would need root and break it.
    before = os.stat("/dev/null")
    write_map("/dev/null", MAP)
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_ino == before.st_ino


@pytest.mark.parametrize("where", ["folder", "missing"])
def test_a_folder_or_a_missing_folder_is_refused_without_temporary_names(tmp_path, where):
    path = tmp_path if where == "folder" else tmp_path / "no" / "map.txt"
    with pytest.raises(OSError) as e:
        write_map(path, MAP)
    assert "hope-rs" not in str(e.value) and ".tmp" not in str(e.value)
    assert ("is a folder" if where == "folder" else "does not exist") in str(e.value)
    assert list(tmp_path.iterdir()) == []


def test_a_byte_order_mark_is_read_past(tmp_path):
    path = tmp_path / "m.txt"
    path.write_bytes(b"\xef\xbb\xbf3\n0\n2\n2\n1\n")
    np.testing.assert_array_equal(read_map(path), MAP)
    lm = tmp_path / "lm.txt"
    lm.write_bytes(b"\xef\xbb\xbf0 5\n17 3\n")
    np.testing.assert_array_equal(read_landmarks(lm), [[0, 5], [17, 3]])


def test_the_swap_hint_names_a_map_as_long_as_b_only(tmp_path):
    """A map of B's length was probably given the other way round; a cut one was not."""
    path = tmp_path / "m.txt"
    path.write_text("0\n1\n2\n3\n")  # B's 4 vertices, A has 5
    with pytest.raises(ValueError, match=r"\(did you swap A and B\?\)"):
        read_map(path, n=5, n_target=4)
    path.write_text("0\n1\n")  # cut short
    with pytest.raises(ValueError, match="has 2 entries but A has 5") as err:
        read_map(path, n=5, n_target=4)
    assert "did you swap" not in str(err.value)
