"""Map files: write them atomically, read them back with their length and range checked.

A map file lists, for each vertex i of A, the vertex of B matched to it. Two formats, chosen by
the file's suffix when writing:

- ``.txt``, ``.csv`` or no suffix: text, one 0-based B index per line (what ``hope-rs match``
  prints), ending with a newline;
- ``.npy``: a NumPy int64 array (``np.save``).

Reading recognises a NumPy file by its content, whatever its name. Files are written to a
temporary name in the target folder and renamed into place, so a reader (or a rerun after a
crash) sees a whole file or none; they get the usual permissions (0666 minus the umask).
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .readers import without_bom

__all__ = [
    "MAP_SUFFIXES",
    "atomic_write",
    "atomic_writes",
    "check_not_an_input",
    "check_output_file",
    "check_writable_folder",
    "read_landmarks",
    "read_map",
    "map_writer",
    "naming_errors",
    "parse_index",
    "same_file",
    "write_map",
]

#: Map file suffixes and their format: "text" (one index per line) or "npy" (NumPy int64).
MAP_SUFFIXES = {".txt": "text", ".csv": "text", "": "text", ".npy": "npy"}

#: Prefix of the temporary files :func:`atomic_write` renames into place.
TEMP_PREFIX = ".hope-rs-"

_NPY_MAGIC = b"\x93NUMPY"
#: A text map of plain digits and line ends only (the common case, read at once).
_PLAIN = re.compile(r"[0-9\r\n]*")
#: One index of a map or landmark file.
_INTEGER = re.compile(r"[+-]?[0-9]+")
_INT64 = range(int(np.iinfo(np.int64).min), int(np.iinfo(np.int64).max) + 1)


def map_format(path: str | os.PathLike) -> str:
    """The format ``write_map`` uses for ``path``: "text" or "npy"; ValueError for others."""
    suffix = Path(path).suffix.lower()
    if suffix not in MAP_SUFFIXES:
        raise ValueError(
            f"map file {os.fspath(path)!r}: unknown suffix {suffix!r}; use .txt or .csv (one "
            "index per line) or .npy (NumPy)"
        )
    return MAP_SUFFIXES[suffix]


def _umask() -> int:
    """The process's umask, read without changing it where the system allows (Linux)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # portable fallback: set and restore
    os.umask(mask)
    return mask


#: Names of a process's own open files, written through the open file itself.
_FD_NAME = re.compile(r"/dev/std(out|err)|/dev/fd/([0-9]+)|/proc/self/fd/([0-9]+)")


def _fd_named(path: str | os.PathLike) -> int | None:
    """The file descriptor ``path`` names (``/dev/stdout`` is 1, ``/dev/fd/3`` is 3), else
    None. Such a name is written through the descriptor: opening it again would truncate a
    file standard output is redirected to (``>> log.txt``), and renaming over it would
    replace that file."""
    m = _FD_NAME.fullmatch(os.path.normpath(os.fspath(path)))
    if m is None:
        return None
    std, fd, proc = m.groups()
    return {"out": 1, "err": 2}[std] if std else int(fd or proc)


def _write_to_fd(fd: int, write: Callable[[io.BufferedWriter], object]) -> None:
    """Write through open file descriptor ``fd`` at its position (appending if it appends),
    after what Python has buffered for it."""
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None and stream.fileno() == fd:
                stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    with os.fdopen(os.dup(fd), "wb") as fh:
        write(fh)


def _file_name_problem(shown: str) -> str | None:
    """Why ``shown`` cannot name a file to write: empty, or ending in a separator without
    being a folder (``m.txt/`` asks for a folder, not a plain file ``m.txt``); else None."""
    if shown == "":
        return "the output names no file (an empty path)"
    if shown.endswith(("/", os.sep)) and not os.path.isdir(shown):
        return f"{shown!r} ends in {shown[-1]!r}, so it names a folder; give a file name"
    return None


def _special(path: str | os.PathLike) -> bool:
    """Whether ``path`` (links followed) exists and is neither a plain file nor a folder: a
    FIFO, a socket or a device such as ``/dev/stdout``."""
    return os.path.exists(path) and not (os.path.isfile(path) or os.path.isdir(path))


def atomic_write(path: str | os.PathLike, write: Callable[[io.BufferedWriter], object]) -> None:
    """Write a file through ``write(binary_file)`` so that it appears whole or not at all.

    The data go to a temporary file in the same folder, are flushed to disk, get the mode a
    plain ``open`` would give (0666 minus the umask; ``mkstemp`` makes 0600) and are renamed
    over ``path``. On any error the temporary file is removed and ``path`` is left as it was.
    A symbolic link is followed (the file it names is replaced, the link kept); a name of one
    of the process's open files (``/dev/stdout``, ``/dev/fd/N``) is written through that file
    at its position, whatever it is redirected to; a FIFO or a device is written in place,
    since it cannot be replaced. A folder, a missing folder, an empty name and one ending in
    ``/`` are refused with a one-line error naming ``path``.
    """
    atomic_writes([(path, write)])


def atomic_writes(items) -> None:
    """Several files as :func:`atomic_write` does one, all or none: ``items`` are
    ``(path, write)`` pairs, and every plain file is written to its temporary file before
    any is renamed into place, so a failure (a full disk) leaves every one as it was."""
    staged: list[tuple[str, str, str]] = []  # (temporary file, target, name as given)
    direct = []  # open files, FIFOs and devices: written in place, once the rest is staged
    try:
        for path, write in items:
            shown = os.fspath(path)
            problem = _file_name_problem(shown)
            if problem is not None:
                raise (FileNotFoundError if shown == "" else NotADirectoryError)(problem)
            if os.path.isdir(shown):
                raise IsADirectoryError(f"{shown!r} is a folder; give a file name")
            fd = _fd_named(shown)
            if fd is not None or _special(shown):
                # Renaming over a FIFO, a socket or a device would replace it with a file.
                direct.append((shown, fd, write))
                continue
            target = os.path.realpath(shown)
            folder = os.path.dirname(target)
            if not os.path.isdir(folder):
                raise FileNotFoundError(f"cannot write {shown!r}: folder {folder!r} does not exist")
            handle, tmp = tempfile.mkstemp(dir=folder, prefix=TEMP_PREFIX, suffix=".tmp")
            staged.append((tmp, target, shown))
            try:
                with os.fdopen(handle, "wb") as fh:
                    write(fh)
                    fh.flush()
                    os.fsync(fh.fileno())
                    os.fchmod(fh.fileno(), 0o666 & ~_umask())
            except OSError as err:
                raise _naming(err, shown) from None
        for shown, fd, write in direct:
            try:
                if fd is not None:
                    _write_to_fd(fd, write)
                else:
                    with open(shown, "wb") as fh:
                        write(fh)
            except OSError as err:
                raise _naming(err, shown) from None
        for tmp, target, shown in staged:
            try:
                os.replace(tmp, target)
            except OSError as err:
                raise _naming(err, shown) from None
    finally:
        for tmp, _, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)


@contextlib.contextmanager
def naming_errors(path: str | os.PathLike):
    """An OSError raised inside, made to name ``path`` when it names no file (a full disk
    or a file-size limit says "File too large", not which)."""
    try:
        yield
    except OSError as err:
        raise _naming(err, os.fspath(path)) from None


def _naming(err: OSError, path: str) -> OSError:
    """``err`` (the disk full or gone) with ``path`` as its file name, so that its message
    says which file could not be written; the same class (``OSError(errno, ...)`` picks the
    subclass). Without an error number (NumPy's short write: "4999 requested and 1008
    written"), an ``OSError`` whose message names ``path``."""
    if err.filename is not None:
        return err
    if err.errno is None:
        return OSError(f"cannot write {path!r}: {err}")
    return OSError(err.errno, err.strerror, path)


def check_writable_folder(
    folder: str | os.PathLike, *, create: bool = False, need_bytes: int = 0, what: str = "output"
) -> Path:
    """Fail early, with a one-line ValueError naming ``folder``, unless files can be created in
    it (a probe file is created and removed) and its disk has ``need_bytes`` free. With
    ``create``, a missing folder is made first. ``what`` names the folder in the message."""
    if os.fspath(folder) == "":  # Path("") is the current folder
        raise ValueError(f"{what} folder names no folder (an empty path)")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{what} {str(folder)!r} exists and is not a folder")
    if not folder.exists():
        if not create:
            raise ValueError(f"{what} folder {str(folder)!r} does not exist; create it first")
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise ValueError(
                f"cannot create {what} folder {str(folder)!r}: {e.strerror or e}"
            ) from None
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=TEMP_PREFIX, suffix=".probe")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise ValueError(
            f"cannot write to {what} folder {str(folder)!r}: {e.strerror or e}"
        ) from None
    if need_bytes > 0:
        try:
            free = shutil.disk_usage(folder).free
        except OSError:
            free = None  # unknown: the writes themselves will say
        if free is not None and free < need_bytes:
            raise ValueError(
                f"{what} folder {str(folder)!r} has {free / 2**20:.1f} MiB free, less than the "
                f"{need_bytes / 2**20:.1f} MiB one entry needs; free some space or choose "
                "another folder"
            )
    return folder


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether the paths ``a`` and ``b`` name one file (links followed; either may not exist
    yet)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        norm = os.path.normcase
        return norm(os.path.realpath(a)) == norm(os.path.realpath(b))


def check_not_an_input(target: str | os.PathLike, inputs, option: str) -> None:
    """Refuse, in one line naming ``option``, an output file that is one of the command's
    ``inputs`` (paths; None for one not given): writing it would overwrite that input."""
    for x in inputs:
        if (
            x is not None
            and os.path.exists(target)
            and os.path.exists(x)
            and os.path.samefile(target, x)
        ):
            raise ValueError(
                f"{option} would write {os.fspath(target)!r}, one of the inputs; name another file"
            )


def check_output_file(path: str | os.PathLike, option: str) -> None:
    """Fail early, with a one-line ValueError naming the ``option``, when the file ``path``
    cannot be written: it is a folder, or its folder (a link's target's) does not take new
    files, or it is a FIFO or device that is not writable."""
    problem = _file_name_problem(os.fspath(path))
    if problem is not None:
        raise ValueError(f"{option}: {problem}")
    if os.path.isdir(path):
        raise ValueError(f"{option} {os.fspath(path)!r} is a folder; give a file name")
    fd = _fd_named(path)
    if fd is not None:
        try:
            writable = (fcntl.fcntl(fd, fcntl.F_GETFL) & os.O_ACCMODE) in (os.O_WRONLY, os.O_RDWR)
        except OSError:
            writable = False
        if not writable:
            raise ValueError(f"{option} {os.fspath(path)!r} is not open for writing")
        return
    if _special(path):
        # A FIFO or a device (/dev/stdout) is written in place (see atomic_write).
        if not os.access(path, os.W_OK):
            raise ValueError(f"{option} {os.fspath(path)!r} is not writable")
        return
    check_writable_folder(os.path.dirname(os.path.realpath(path)))


def write_map(path: str | os.PathLike, mapping) -> None:
    """Write a map file atomically, in the format its suffix names.

    Parameters
    ----------
    path : str or PathLike
        ``.txt``/``.csv``/no suffix: one 0-based B index per line; ``.npy``: NumPy int64.
        Other suffixes raise ValueError (before anything is written).
    mapping : (n_a,) array_like of int
        ``mapping[i]`` is the vertex of B matched to vertex i of A.
    """
    atomic_write(path, map_writer(path, mapping))


def map_writer(path: str | os.PathLike, mapping) -> Callable[[io.BufferedWriter], object]:
    """What :func:`write_map` writes to ``path``, as a function of the open file (for
    :func:`atomic_writes`); ValueError for a bad suffix or map, before anything is written."""
    fmt = map_format(path)
    arr = np.asarray(mapping)
    if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"a map must be a 1-D integer array, got {arr.dtype} of shape {arr.shape}")
    if arr.size and arr.min() < 0:
        raise ValueError(f"a map holds vertex indices >= 0, got {arr.min()} (read_map refuses it)")
    if arr.size and arr.max() > np.iinfo(np.int64).max:
        raise ValueError(f"a map's vertex indices must fit in int64, got {arr.max()}")
    arr = arr.astype(np.int64, copy=False)
    if fmt == "npy":
        return lambda fh: np.save(fh, arr, allow_pickle=False)
    text = "".join(f"{x}\n" for x in arr.tolist())
    return lambda fh: fh.write(text.encode("ascii"))


def read_map(
    path: str | os.PathLike, n: int | None = None, n_target: int | None = None
) -> np.ndarray:
    """Read a map file written by :func:`write_map` (or ``hope-rs match``), checked.

    Parameters
    ----------
    path : str or PathLike
        A NumPy ``.npy`` file (recognised by its content) or text, one 0-based index per line.
    n : int, optional
        Expected length (vertices of A).
    n_target : int, optional
        Indices must lie in ``[0, n_target)`` (vertices of B).

    Returns
    -------
    (n,) int64 ndarray

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A one-line message naming the file (and, in a text map, the line): unreadable, not
        one integer a line, wrong length or range.
    """
    name = os.fspath(path)
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"no such map file: {name!r}") from None
    except OSError as e:
        raise ValueError(f"cannot read map {name!r}: {e.strerror or e}") from None
    if data.startswith(_NPY_MAGIC):
        try:
            arr = np.load(io.BytesIO(data), allow_pickle=False)
        except Exception as e:  # noqa: BLE001 - any failure to parse is a damaged file
            raise ValueError(f"map {name!r} is a damaged NumPy file ({e})") from None
        if not isinstance(arr, np.ndarray) or arr.ndim != 1:
            raise ValueError(f"map {name!r} must hold a 1-D array, got shape {np.shape(arr)}")
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise ValueError(f"map {name!r} must hold integers, got dtype {arr.dtype}")
        if arr.size and arr.dtype.kind == "u" and arr.max() > np.uint64(np.iinfo(np.int64).max):
            raise ValueError(f"map {name!r} holds index {arr.max()}, too large for a vertex index")
        arr = arr.astype(np.int64)
        text = None
    else:
        arr, text = _text_map(name, without_bom(data))
    if n is not None and arr.size != n:
        # The swap is worth naming only when the length is B's vertex count.
        swapped = " (did you swap A and B?)" if arr.size == n_target else ""
        raise ValueError(
            f"map {name!r} has {arr.size} entries but A has {n} vertices; it must list one B "
            f"vertex per vertex of A{swapped}"
        )
    if arr.size and arr.min() < 0:  # a NumPy file's (a text map's is refused with its line)
        raise ValueError(f"map {name!r} holds a negative index ({arr.min()}); indices are 0-based")
    if arr.size and n_target is not None and arr.max() >= n_target:
        # A text map's first index out of range, named by its line; a NumPy file's largest.
        i = int(np.argmax(arr >= n_target)) if text is not None else int(np.argmax(arr))
        where = f"map {name!r}" if text is None else f"{name}:{_entry_line(text, i)}: the map"
        raise ValueError(
            f"{where} holds index {arr[i]} but B has {n_target} vertices (0-based indices "
            "must be below the vertex count)"
        )
    return arr


def parse_index(word: str) -> int | None:
    """``word`` as an int when it is a signed integer in ASCII digits (``int`` would also take
    "1_0" for 10 and other scripts' digits), else ``None``; OverflowError when it does not fit
    int64 (told from its digits first: ``int`` refuses 4,300 of them)."""
    if not _INTEGER.fullmatch(word):
        return None
    if len(word.lstrip("+-0")) > 19 or int(word) not in _INT64:
        raise OverflowError(word)
    return int(word)


def _lines(text: str) -> list[str]:
    """``text``'s lines, each ended by LF, CR LF or CR."""
    return text.replace("\r\n", "\n").replace("\r", "\n").split("\n")


def _entry_line(text: str, i: int) -> int:
    """The line number (from 1) of entry ``i`` (from 0) of a text map: its ``i``-th line that
    is not blank."""
    for n, line in enumerate(_lines(text), 1):
        if line.strip():
            if i == 0:
                return n
            i -= 1
    raise IndexError("no such entry")


def _text_map(name: str, data: bytes) -> tuple[np.ndarray, str]:
    """The entries of a text map file ``name`` (its bytes, without a BOM) and its text: one
    0-based index per line, blank lines skipped; a bad line is refused naming its number."""
    rule = "expected one 0-based integer index per line, or a .npy array"
    try:
        text = data.decode("ascii")
    except UnicodeDecodeError as e:
        at = len(_lines(data[: e.start].decode("ascii")))  # LF, CR LF or CR, as below
        raise ValueError(
            f"{name}:{at}: byte 0x{data[e.start]:02x} is not text; this is not a map file ({rule})"
        ) from None
    if _PLAIN.fullmatch(text):  # as write_map writes it: parsed at once
        words = text.split()
        if not words or max(map(len, words)) <= 18:  # below 10**18: fits int64
            return np.array(words, dtype=np.int64), text
    values = []
    for n, line in enumerate(_lines(text), 1):
        words = line.split()
        if not words:
            continue
        shown = line.strip()[:80]
        if len(words) > 1 and not words[0].startswith("#"):
            raise ValueError(f"{name}:{n}: {shown!r} holds {len(words)} values ({rule})")
        try:
            value = parse_index(words[0])
        except OverflowError:
            raise ValueError(
                f"{name}:{n}: index {shown!r} is too large for a vertex index"
            ) from None
        if value is None:
            raise ValueError(
                f"{name}:{n}: {shown!r} is not a vertex index; this is not a map file ({rule})"
            )
        if value < 0:
            raise ValueError(f"{name}:{n}: negative index {value}; indices are 0-based")
        values.append(value)
    return np.array(values, dtype=np.int64), text


def read_landmarks(
    path: str | os.PathLike, *, n_a: int | None = None, n_b: int | None = None
) -> np.ndarray:
    """Read a landmark file: one ``A_VERTEX B_VERTEX`` pair per line (0-based, separated by
    spaces, tabs or a comma; ``#`` starts a comment; blank lines are skipped).

    Parameters
    ----------
    n_a, n_b : int, keyword-only, optional
        Vertex counts of A and B: an index out of range is then refused naming its line.

    Returns
    -------
    (m, 2) int64 ndarray
        Checked for form (and range, given the counts); :func:`hope_rs.match` checks the
        indices against the meshes.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        A one-line message naming the file and the first bad line.
    """
    name = os.fspath(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FileNotFoundError(f"no such landmark file: {name!r}") from None
    except UnicodeDecodeError:
        raise ValueError(
            f"landmark file {name!r} is not text; it lists one 'A_VERTEX B_VERTEX' pair of "
            "0-based indices per line"
        ) from None
    except OSError as e:
        raise ValueError(f"cannot read landmark file {name!r}: {e.strerror or e}") from None
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        words = line.split("#", 1)[0].replace(",", " ").split()
        if not words:
            continue
        # ASCII digits only: int() would take "1_0" for 10 and other scripts' digits.
        if len(words) != 2 or not all(_INTEGER.fullmatch(w) for w in words):
            raise ValueError(
                f"{name}:{n}: expected two 0-based vertex indices 'A_VERTEX B_VERTEX', got "
                f"{line.strip()!r}"
            )
        # Past 19 digits no index fits int64 (and int() refuses past 4,300 digits).
        if any(len(w.lstrip("+-")) > 19 or int(w) not in _INT64 for w in words):
            raise ValueError(f"{name}:{n}: vertex index too large, got {line.strip()[:80]!r}")
        row = (int(words[0]), int(words[1]))
        for v, count, mesh in ((row[0], n_a, "A"), (row[1], n_b, "B")):
            if count is not None and not 0 <= v < count:
                raise ValueError(
                    f"{name}:{n}: vertex {v} is not a vertex of {mesh}, which has {count} "
                    f"(0-based indices 0..{count - 1})"
                )
        rows.append(row)
    return np.array(rows, dtype=np.int64).reshape(-1, 2)


def text_map_is_complete(path: str | os.PathLike) -> bool:
    """A text map ends with a newline (a file cut short inside its last number does not); NumPy
    files check their own length."""
    with open(path, "rb") as fh:
        if fh.read(len(_NPY_MAGIC)) == _NPY_MAGIC:
            return True
        fh.seek(0, os.SEEK_END)
        if fh.tell() == 0:
            return False
        fh.seek(-1, os.SEEK_END)
        return fh.read(1) == b"\n"
