"""Safe output files: write to a temporary file, then rename; provenance hashes."""

from __future__ import annotations

import contextlib
import hashlib
import os
import secrets
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from holoprobe.errors import InputError

__all__ = ["atomic_write", "file_sha256", "warm_sha256"]


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _reserve_temp(directory: Path, name: str, suffix: str, *, attempts: int = 100) -> Path:
    """Create an empty, uniquely named file in ``directory`` (mode 0o666 minus umask)."""
    for _ in range(attempts):
        candidate = directory / f".{name}.{secrets.token_hex(6)}.tmp{suffix}"
        try:
            fd = os.open(candidate, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return candidate
    raise InputError(f"could not create a temporary file in {directory}", file=str(directory))


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    protect: Iterable[str | os.PathLike] = (),
    make_parents: bool = True,
) -> Iterator[Path]:
    """Write a file atomically: yield a temporary path, then rename it onto ``path``.

    The temporary file lives in the same directory as ``path`` (so the final
    :func:`os.replace` is atomic on POSIX and Windows). If the body of the
    ``with`` block raises, the temporary file is removed and ``path`` is left
    exactly as it was (absent, or the previous file).

    Parameters
    ----------
    path : str or PathLike
        The final output file.
    overwrite : bool
        Replace ``path`` if it exists. Default: refuse with :class:`InputError`.
    protect : iterable of str or PathLike
        Input files of the computation; ``path`` may never be one of them, even
        with ``overwrite=True`` (compared with :func:`os.path.samefile`).
    make_parents : bool
        Create missing parent directories of ``path``.

    Yields
    ------
    pathlib.Path
        The temporary file to write (it exists, empty; its suffix is that of
        ``path`` so that writers that look at the extension behave).

    Raises
    ------
    InputError
        If ``path`` exists and ``overwrite`` is false, if ``path`` is one of the
        protected inputs, or if ``path`` is a directory.

    Examples
    --------
    >>> with atomic_write(out_dir / "summary.json") as tmp:  # doctest: +SKIP
    ...     tmp.write_text(text)
    """
    target = Path(path)
    for source in protect:
        if _same_file(target, Path(source)):
            raise InputError("refusing to overwrite an input file", file=str(target))
    if target.is_dir():
        raise InputError("is a directory, expected a file path", file=str(target))
    if target.exists() and not overwrite:
        raise InputError("already exists; pass overwrite=True to replace it", file=str(target))
    directory = target.parent
    if make_parents:
        directory.mkdir(parents=True, exist_ok=True)
    elif not directory.is_dir():
        raise InputError("the output directory does not exist", file=str(directory))
    tmp = _reserve_temp(directory, target.name, target.suffix)
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def file_sha256(path: str | os.PathLike, *, chunk_bytes: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes as a hexadecimal string (for provenance records).

    Parameters
    ----------
    path : str or PathLike
        The file.
    chunk_bytes : int
        Read size in bytes (memory use is bounded by it).

    Returns
    -------
    str
        64 hexadecimal characters.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError("no such file", file=str(p))
    st = p.stat()  # a file changed since it was hashed has another key
    key = (str(p.resolve()), st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    with _SHA_LOCK:
        lock = _SHA_KEY_LOCKS.setdefault(key, threading.Lock())
    with lock:  # a second caller waits for the first one's digest
        if key not in _SHA_DIGESTS:
            digest = hashlib.sha256()
            with p.open("rb") as fh:
                for block in iter(lambda: fh.read(chunk_bytes), b""):
                    digest.update(block)
            _SHA_DIGESTS[key] = digest.hexdigest()
        return _SHA_DIGESTS[key]


_SHA_LOCK = threading.Lock()
_SHA_KEY_LOCKS: dict[tuple[str, int, int, int, int], threading.Lock] = {}
_SHA_DIGESTS: dict[tuple[str, int, int, int, int], str] = {}
""":func:`file_sha256`'s digests in this process, by (resolved path, inode, size,
modification time in ns, status-change time in ns). The status-change time (ctime) is
there because the modification time can be set back (``cp -p``, ``rsync -t``,
``os.utime``) after an in-place rewrite of the same size, the ctime cannot; a rewrite
within the file system's ctime granularity (a kernel tick on older kernels) of the
hashing would still go unseen."""


def warm_sha256(paths: Iterable[str | os.PathLike]) -> None:
    """Compute and keep (:func:`file_sha256`) the digests of the existing files of
    ``paths``, so that a later call for the provenance finds them ready; errors are left
    to that call.

    Meant for a thread beside a long computation (``holoprobe.workflow.characterize``
    runs it in a :class:`holoprobe.signal.Threads` block around the estimation): reading
    and hashing release the GIL, so the digests (≈ 0.1 s CPU for a 132 MB full-size scan)
    cost the otherwise idle core instead of the time of writing the outputs.
    """
    for p in paths:
        with contextlib.suppress(Exception):
            if Path(p).is_file():
                file_sha256(p)
