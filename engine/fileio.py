"""File input/output guards: atomic writes, checked output paths, a guarded TOML reader.

Atomic output: the data goes to a temporary file beside the target, then is renamed onto it.  A
crash or a full disk never leaves a half-written file where the user's file was, and the previous
file stays intact.  A symlink stays a symlink (the file it points to is replaced); a target that is
not a regular file (a terminal, a pipe, ``/dev/stdout``) is written into once the content is complete
(a rename would have put a regular file in its place: as root, over ``/dev/stdout`` itself).  The
temporary file is named ``.NAME.winder-PID-XXXX.SUFFIX``; one left behind by a killed process (its PID
no longer runs) is removed by the next write into the same folder.

Every failure is an :class:`~engine.errors.InputError` naming the file: the target is a folder, its
folder is missing, no permission, the disk is full.

:func:`loads_toml` parses TOML text with a size limit and turns every parser failure (a syntax
error, a nesting deep enough to exhaust the parser's recursion, an integer of thousands of digits)
into an :class:`InputError` naming the file and the line.
"""

from __future__ import annotations

import errno
import os
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from engine.errors import InputError

MAX_TOML_BYTES = 16 * 2**20
"""Largest TOML document read (16 MiB; a job with a 200 000-point sketch is about 5 MB)."""

MAX_TOML_DEPTH = 64
"""Deepest nesting of arrays and inline tables accepted in a TOML document."""

_TMP_TAG = ".winder-"
_STALE_AGE_S = 60.0  # a temporary file younger than this is left alone even if its PID is gone


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # exists (another user's) or unknown: keep the file
    return True


def remove_stale_temporaries(directory: str | Path) -> int:
    """Remove temporary files of atomic writes whose process is gone; returns how many were removed."""
    removed = 0
    pat = re.compile(r"^\..+" + re.escape(_TMP_TAG) + r"(\d+)-[^/]*$")
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return 0
    now = time.time()
    for e in entries:
        m = pat.match(e.name)
        if not m:
            continue
        try:
            if not e.is_file(follow_symlinks=False) or now - e.stat(follow_symlinks=False).st_mtime < _STALE_AGE_S:
                continue
            if _pid_alive(int(m.group(1))):
                continue
            os.unlink(e.path)
            removed += 1
        except OSError:
            continue
    return removed


def check_output_path(path: str | Path, what: str = "output") -> Path:
    """Refuse, before any work, an output path that cannot be written.

    Raises :class:`InputError` naming the file when the path is a folder, its folder does not exist
    or is not a folder, or the folder (or an existing file) is not writable.
    """
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise InputError(f"cannot write the {what} file: the path names a folder, not a file", file=str(path))
    try:
        return _check_output_path(p, what)
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise _os_error(exc, p) from None


def _stream_target(p: Path) -> bool:
    """Whether ``p`` (followed through symlinks) exists and is not a regular file or a folder: a terminal,
    a pipe or FIFO, ``/dev/stdout`` or ``/dev/null``.  Such an output is written into, not replaced (a
    rename would put a regular file where the device or its symlink was)."""
    import stat

    try:
        mode = os.stat(p).st_mode
    except OSError:
        return False
    return not stat.S_ISREG(mode) and not stat.S_ISDIR(mode)


def _replace_target(p: Path) -> Path:
    """The file an atomic write renames onto: ``p`` itself, or, when ``p`` is a symlink, the file it points to
    (followed to the end, existing or not), so that the link stays a link."""
    return Path(os.path.realpath(p)) if p.is_symlink() else p


def _check_output_path(p: Path, what: str) -> Path:
    why = f"cannot write the {what} file"
    if _stream_target(p):
        if not os.access(p, os.W_OK):
            raise InputError(f"{why}: no permission to write to it", file=p)
        return p
    if p.is_dir():
        raise InputError(f"{why}: the path is a folder; give a file name", file=p)
    given, p = p, _replace_target(p)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise InputError(f"{why}: the folder {str(parent)!r} does not exist", file=p)
    if not parent.is_dir():
        raise InputError(f"{why}: {str(parent)!r} is not a folder", file=p)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{why}: no permission to write in the folder {str(parent)!r}", file=p)
    if p.exists() and not os.access(p, os.W_OK) and not os.access(parent, os.W_OK):
        raise InputError(f"{why}: no permission to replace it", file=p)
    return given


def _write_through(target: Path, writer: Callable[[str], object], suffix: str) -> Path:
    """:func:`atomic_write_with` into a device or pipe: the content is made in a temporary file first (a
    writer that fails sends nothing), then copied into ``target``."""
    import shutil

    try:
        fd, tmp = tempfile.mkstemp(prefix=f"winder-{os.getpid()}-", suffix=suffix or target.suffix)
    except OSError as exc:
        raise _os_error(exc, target) from None
    os.close(fd)
    try:
        writer(tmp)
        with open(tmp, "rb") as src, open(target, "wb") as dst:
            shutil.copyfileobj(src, dst)
    except OSError as exc:
        raise _os_error(exc, target) from None
    finally:
        try:
            os.unlink(tmp)
        except OSError:
            pass
    return target


def _os_error(exc: OSError, path: Path) -> InputError:
    code = exc.errno
    if code in (errno.ENOSPC, errno.EDQUOT):
        why = "the disk is full; the previous file (if any) is unchanged"
    elif code in (errno.EACCES, errno.EPERM, errno.EROFS):
        why = "no permission to write here"
    elif code == errno.EISDIR:
        why = "the path is a folder; give a file name"
    elif code == errno.ENOENT:
        why = "the folder does not exist"
    elif code == errno.ENAMETOOLONG:
        why = "the file name is too long"
    else:
        why = exc.strerror or str(exc)
    return InputError(f"cannot write the file: {why}", file=path)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    return atomic_write_with(path, lambda tmp: Path(tmp).write_bytes(data))


def atomic_write_text(path: str | Path, text: str, newline: str | None = "\n") -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; ``newline`` as in :func:`open`."""

    def _write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8", newline=newline) as fh:
            fh.write(text)

    return atomic_write_with(path, _write)


def atomic_write_with(path: str | Path, writer: Callable[[str], object], suffix: str = "") -> Path:
    """Call ``writer(tmp_path)`` to produce the file, then rename it onto ``path``.

    ``suffix`` is given to the temporary name (some writers, e.g. STEP/STL exporters, pick the
    format from the extension; by default the target's suffix is used).  An :class:`OSError`
    (folder, permission, full disk) becomes an :class:`InputError` naming ``path``; the previous
    file stays as it was and the temporary file is removed.

    A symlink stays a symlink: the file it points to is replaced.  A target that is not a regular file
    (a terminal, a pipe, ``/dev/stdout``) is written into once the temporary file is complete.
    """
    given = check_output_path(path)
    if _stream_target(given):
        return _write_through(given, writer, suffix)
    path = _replace_target(given)
    directory = path.parent if str(path.parent) else Path(".")
    remove_stale_temporaries(directory)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}{_TMP_TAG}{os.getpid()}-",
                                   suffix=suffix or path.suffix, dir=directory)
    except OSError as exc:
        raise _os_error(exc, given) from None
    os.close(fd)
    try:
        writer(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        if path.exists():
            try:
                os.chmod(tmp, path.stat().st_mode & 0o7777)
            except OSError:
                pass
        else:
            os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise _os_error(exc, given) from None
        raise
    return given


# ------------------------------------------------------------------------------------------------
# Guarded TOML reading
# ------------------------------------------------------------------------------------------------
def _deepest_line(text: str) -> tuple[int, int]:
    """(line, depth) where the nesting of ``[``/``{`` outside strings and comments is deepest (approximate)."""
    depth = best = 0
    best_line = line = 1
    in_str: str | None = None
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            if in_str in ('"', "'"):
                in_str = None
        elif in_str:
            if text.startswith(in_str, i):
                i += len(in_str)
                in_str = None
                continue
            if c == "\\" and in_str in ('"', '"""'):
                i += 2
                continue
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "\"'":
            in_str = c * 3 if text.startswith(c * 3, i) else c
            i += len(in_str)
            continue
        elif c in "[{":
            depth += 1
            if depth > best:
                best, best_line = depth, line
        elif c in "]}":
            depth = max(depth - 1, 0)
        i += 1
    return best_line, best


def loads_toml(text: str, file: str | Path | None = None) -> dict[str, Any]:
    """Parse TOML ``text``; any failure is an :class:`InputError` naming ``file`` and the line.

    Refuses documents larger than :data:`MAX_TOML_BYTES` characters and nesting deeper than
    :data:`MAX_TOML_DEPTH` (the parser is recursive).
    """
    import tomllib

    if len(text) > MAX_TOML_BYTES:
        raise InputError(f"the TOML document is {len(text)} characters long (at most {MAX_TOML_BYTES})", file=file)
    if text.count("[") + text.count("{") > MAX_TOML_DEPTH:  # cheap: only then can the nesting be too deep
        line, depth = _deepest_line(text)
        if depth > MAX_TOML_DEPTH:
            raise InputError(f"arrays or tables nested {depth} deep (at most {MAX_TOML_DEPTH})", file=file, line=line)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = re.search(r"line (\d+)", msg)
        raise InputError(f"not valid TOML: {msg}", file=file, line=int(m.group(1)) if m else None) from None
    except RecursionError:
        line, depth = _deepest_line(text)
        raise InputError(f"not valid TOML: nested too deeply ({depth} levels)", file=file, line=line) from None
    except MemoryError:
        raise InputError("not valid TOML: the document is too large to read", file=file) from None
    except Exception as exc:  # noqa: BLE001 - the parser sees arbitrary text; any failure is bad input
        raise InputError(f"not valid TOML: {exc}", file=file) from None


def read_text_limited(path: str | Path, limit: int = MAX_TOML_BYTES, what: str = "file") -> str:
    """UTF-8 text of ``path``, refusing folders, files over ``limit`` bytes and non-UTF-8 data."""
    p = Path(path)
    try:
        if p.is_dir():
            raise InputError(f"{what} expected, found a folder", file=p)
        size = p.stat().st_size
        if size > limit:
            raise InputError(f"the {what} is {size} bytes (at most {limit})", file=p)
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{what} not found", file=p) from None
    except OSError as exc:
        raise InputError(f"cannot read the {what}: {exc.strerror or exc}", file=p) from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError("not a UTF-8 text file", file=p, line=line) from None


# ------------------------------------------------------------------------------------------------
# Guarded .npz reading
# ------------------------------------------------------------------------------------------------
def load_npz_arrays(path: str | Path, ndims: dict[str, int], max_bytes: int | None = None) -> dict[str, Any]:
    """The arrays ``ndims`` names from an ``.npz`` file, as finite float64 arrays of the given ``ndim``.

    1-D arrays are accepted where 2-D ones are asked for (one column).  Refuses, with an
    :class:`InputError` naming the file and the array: a missing or unreadable file, a folder, not an
    npz archive, pickled objects, arrays whose uncompressed size exceeds ``max_bytes`` (default a
    quarter of the memory budget: a small archive can expand without bound), a missing array, a
    non-numeric dtype, the wrong number of dimensions, non-finite values.
    """
    import zipfile

    import numpy as np

    from engine import budget

    p = Path(path)
    limit = budget.max_memory_bytes() // 4 if max_bytes is None else int(max_bytes)
    if p.is_dir():
        raise InputError("expected an .npz file, found a folder", file=p)
    if not p.exists():
        raise InputError("file not found", file=p)
    try:
        with zipfile.ZipFile(p) as zf:
            total = sum(i.file_size for i in zf.infolist())
            for name in ndims:  # the size each array header declares, before numpy allocates it
                if f"{name}.npy" not in zf.namelist():
                    continue
                with zf.open(f"{name}.npy") as fh:
                    version = np.lib.format.read_magic(fh)
                    if version == (1, 0):
                        shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
                    elif version == (2, 0):
                        shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
                    else:
                        raise InputError(f"array {name!r}: .npy format version {version} is not supported", file=p,
                                         field=name)
                declared = float(np.prod([float(x) for x in shape])) * dtype.itemsize
                if declared > limit:
                    raise InputError(f"array {name!r} declares shape {shape} ({budget.fmt_bytes(declared)}), more "
                                     f"than {budget.fmt_bytes(limit)} (a quarter of the memory budget)", file=p,
                                     field=name)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - zip and npy headers of arbitrary bytes
        raise InputError(f"not a readable .npz file (a zip archive of arrays): {exc}", file=p) from None
    if total > limit:
        raise InputError(f"the arrays expand to {budget.fmt_bytes(total)}, more than {budget.fmt_bytes(limit)} "
                         "(a quarter of the memory budget)", file=p)
    out: dict[str, Any] = {}
    try:
        with np.load(p, allow_pickle=False) as z:
            missing = [k for k in ndims if k not in z.files]
            if missing:
                raise InputError(f"arrays {missing} missing (has {sorted(z.files)})", file=p)
            for name, nd in ndims.items():
                a = z[name]
                if a.dtype.kind not in "biuf":
                    raise InputError(f"array {name!r} has dtype {a.dtype}, expected numbers", file=p, field=name)
                if a.ndim == 1 and nd == 2:
                    a = a[:, None]
                if a.ndim != nd:
                    raise InputError(f"array {name!r} has {a.ndim} dimensions {a.shape}, expected {nd}", file=p,
                                     field=name)
                a = np.asarray(a, dtype=float)
                bad = np.flatnonzero(~np.isfinite(a.reshape(-1)))
                if bad.size:
                    raise InputError(f"array {name!r} has {bad.size} non-finite value(s) (first at flat index "
                                     f"{int(bad[0])})", file=p, field=name)
                out[name] = a
    except InputError:
        raise
    except MemoryError:
        raise InputError("the arrays do not fit in memory", file=p) from None
    except Exception as exc:  # noqa: BLE001 - numpy's reader sees arbitrary bytes; any failure is bad input
        raise InputError(f"not a readable .npz file: {type(exc).__name__}: {exc}", file=p) from None
    return out
