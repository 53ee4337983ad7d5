"""Reading input files safely: only regular files, and no more than a size limit.

Every reader of `diffsusp.io` and `diffsusp.measure` goes through `read_input`: a path that is a
device (`/dev/zero`), a FIFO or a socket — directly or through a link — is refused before it is
opened (opening a FIFO would block), and a file larger than the limit is refused before it is
read (a 50 MB model file would take minutes and gigabytes to parse).

**Limits** (bytes; `$DIFFSUSP_MAX_FILE_MB` overrides both, in MiB, as does the command's
`--max-file-mb` option):

- model files (`.toml`, `.adm`, `.json`, `.lcf`, property files): `MODEL_LIMIT`, 16 MiB — the
  largest shipped model is 9 kB; a 10 000-bushing model is about 4 MiB;
- tables (load cases, measurements; CSV or Parquet): `TABLE_LIMIT`, 512 MiB.
"""

import contextlib
import os
import pathlib
import stat
import tempfile

from ..errors import ModelFileError

MiB = 1 << 20
MODEL_LIMIT = 16 * MiB
"""Largest model file read (bytes), unless `$DIFFSUSP_MAX_FILE_MB` says otherwise."""
TABLE_LIMIT = 512 * MiB
"""Largest table read (bytes), unless `$DIFFSUSP_MAX_FILE_MB` says otherwise."""
ENVIRONMENT = "DIFFSUSP_MAX_FILE_MB"


def limit(kind: str = "model") -> int:
    """The size limit (bytes) for a `kind` of file ("model" or "table")."""
    text = os.environ.get(ENVIRONMENT, "").strip()
    if text:
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not value > 0 or value == float("inf"):
            raise ModelFileError(f"${ENVIRONMENT} must be a positive number of MiB; got "
                                 f"'{text}'.", path=None)
        return int(value * MiB)
    return TABLE_LIMIT if kind == "table" else MODEL_LIMIT


def _size(n: int) -> str:
    return f"{n / MiB:.1f} MiB" if n >= MiB else f"{n} bytes"


def check_input(path, what: str, kind: str = "model") -> int:
    """Check that `path` is a regular file no larger than the limit; return its size.

    **Raises:** `FileNotFoundError` (no such file, as `open` would), `ModelFileError` for a
    directory, a device, a FIFO or socket, an unreadable file or one above the limit.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as e:
        raise ModelFileError(f"cannot read the {what}: {getattr(e, 'strerror', None) or e}.",
                             path=path) from None
    mode = info.st_mode
    if stat.S_ISDIR(mode):
        raise ModelFileError(f"is a directory, not a {what}.", path=path)
    if not stat.S_ISREG(mode):
        kind_text = ("a character device" if stat.S_ISCHR(mode) else "a block device"
                     if stat.S_ISBLK(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
                     else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
        raise ModelFileError(f"is {kind_text}, not a regular file; give the path of the {what} "
                             "on disk.", path=path)
    bound = limit(kind)
    if info.st_size > bound:
        raise ModelFileError(
            f"the {what} is {_size(info.st_size)}, more than the limit of {_size(bound)}; "
            f"raise it with --max-file-mb or ${ENVIRONMENT} if the file is meant to be this "
            "large.", path=path)
    return info.st_size


def read_input(path, what: str, kind: str = "model") -> bytes:
    """The bytes of `path`, after `check_input`; a file that grows past the limit while it is
    read is refused too."""
    check_input(path, what, kind)
    bound = limit(kind)
    try:
        with open(path, "rb") as f:
            data = f.read(bound + 1)
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as e:
        raise ModelFileError(f"cannot read the {what}: {getattr(e, 'strerror', None) or e}.",
                             path=path) from None
    if len(data) > bound:
        raise ModelFileError(f"the {what} is larger than the limit of {_size(bound)}; "
                             f"raise it with --max-file-mb or ${ENVIRONMENT}.", path=path)
    return data


def current_umask() -> int:
    """The process's file-creation mask (read without changing it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path, text: str) -> None:
    """Write `text` (UTF-8) to `path` through a temporary file in the same folder, renamed over
    `path` at the end: an interrupted or failed write never leaves a truncated file under the
    final name (a reader sees the old file or the new one). The file gets the permissions a
    plain `open` would give it (0666 less the umask), not the temporary file's 0600."""
    path = pathlib.Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
