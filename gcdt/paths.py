"""Where generated bulk (datasets, checkpoints, logs, executed notebooks) lives."""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from gcdt.errors import GcdtError

#: Environment variable that relocates the artifacts folder (e.g. to a scratch disk).
ARTIFACTS_ENV = "GCDT_ARTIFACTS"

REPO_ROOT = Path(__file__).resolve().parent.parent


def artifacts_dir() -> Path:
    """The git-ignored artifacts folder: `$GCDT_ARTIFACTS`, else `<repo>/artifacts`."""
    return Path(os.environ.get(ARTIFACTS_ENV) or REPO_ROOT / "artifacts")


#: Minari's own variable for its datasets folder; gcdt's default is `<artifacts>/minari`.
MINARI_ENV = "MINARI_DATASETS_PATH"


def minari_dir() -> Path:
    """Where gcdt reads and writes Minari datasets: `$MINARI_DATASETS_PATH`, else
    `<artifacts>/minari` (not Minari's `~/.minari/datasets`: bulk stays in the artifacts)."""
    return Path(os.environ.get(MINARI_ENV) or artifacts_dir() / "minari").resolve()


#: Environment variable that points results/ and figures/ at a working reproduction's own
#: folder (`make reproduce` sets it), so a user's runs never mix with the published ones.
OUTPUTS_ENV = "GCDT_OUTPUTS"


def outputs_root() -> Path:
    """The folder holding `results/<profile>/` and `figures/<profile>/`: `$GCDT_OUTPUTS`, else
    the repository (the published results). A relative `$GCDT_OUTPUTS` is taken from the
    repository's root, so notebooks (run in notebooks/) and Ray workers find the same folder."""
    return (REPO_ROOT / (os.environ.get(OUTPUTS_ENV) or ".")).resolve()


def is_published(root: str | Path | None = None) -> bool:
    """Whether `root` (default `outputs_root()`) is the repository's published results."""
    return Path(root or outputs_root()).resolve() == REPO_ROOT.resolve()


def reproduction_root() -> Path:
    """A reproduction's own folder: `$GCDT_OUTPUTS`, else `<artifacts>/reproduce` (what
    `make reproduce` fills by default)."""
    if os.environ.get(OUTPUTS_ENV):
        return outputs_root()
    return (REPO_ROOT / artifacts_dir() / "reproduce").resolve()


def results_dir(profile: str, root: str | Path | None = None) -> Path:
    """A profile's results (run files, tables, report) under `root` (default `outputs_root()`)."""
    return Path(root or outputs_root()) / "results" / profile


def figures_dir(profile: str, root: str | Path | None = None) -> Path:
    """A profile's figures under `root` (default `outputs_root()`)."""
    return Path(root or outputs_root()) / "figures" / profile


def write_json_atomic(path: str | Path, data: Any) -> Path:
    """Write `data` as JSON to `path` via a temp file and a rename: never half a file."""
    path = Path(path)
    with atomic_write(path) as f:
        json.dump(data, f, indent=2)
        f.write("\n")
    return path


@contextlib.contextmanager
def atomic_write(path: str | Path, binary: bool = False) -> Iterator[IO[Any]]:
    """An open temp file in `path`'s folder (made if missing), renamed to `path` on success and
    removed on failure, so that no reader ever sees half a file.

    The file gets the mode a plain `open(path, "w")` gives (0o666 less the umask, or what the
    folder's default ACL says), not `tempfile.mkstemp`'s 0o600: other users of a shared machine
    can read datasets, checkpoints and results. Text is UTF-8, written without newline
    translation.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _create_temp(path)
    try:
        how = {"mode": "wb"} if binary else {"mode": "w", "encoding": "utf-8", "newline": ""}
        with os.fdopen(fd, **how) as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def swap_dirs(a: str | Path, b: str | Path) -> None:
    """Exchange the folders `a` and `b` (both must exist, on one file system): how a folder
    is replaced whole, by swapping a finished copy in and then deleting the old one.

    On Linux one `renameat2(RENAME_EXCHANGE)` call swaps them, so a reader sees the old folder
    or the new one, never neither. Where the call is missing (another OS, an old kernel or C
    library, a file system without it) three renames do it, and a failed second rename puts
    the first one back.
    """
    a, b = Path(a), Path(b)
    if _exchange(a, b):
        return
    aside = b.with_name(f".{b.name}.{secrets.token_hex(4)}.swap")
    os.rename(b, aside)
    try:
        os.rename(a, b)
    except BaseException:
        os.rename(aside, b)
        raise
    os.rename(aside, a)


def _exchange(a: Path, b: Path) -> bool:
    """Swap `a` and `b` with Linux's `renameat2(RENAME_EXCHANGE)`; False where it is missing."""
    import ctypes
    import errno

    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError, TypeError):  # not glibc >= 2.28, or not Linux
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p]
    renameat2.argtypes += [ctypes.c_uint]
    at_cwd, exchange = -100, 2  # AT_FDCWD, RENAME_EXCHANGE (linux/fcntl.h, linux/fs.h)
    if renameat2(at_cwd, os.fsencode(a), at_cwd, os.fsencode(b), exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):  # no kernel or file-system support
        return False
    raise OSError(code, os.strerror(code), str(a), None, str(b))


def _create_temp(path: Path) -> tuple[int, Path]:
    """A new, exclusive `.NAME.RANDOM.tmp` next to `path`, created as `open()` would create it.

    The kernel applies the umask to the 0o666 asked for here, which avoids reading the
    process-wide umask (`os.umask` can only be read by setting it: racy across threads).
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    flags |= getattr(os, "O_BINARY", 0)  # Windows: no newline translation below fdopen
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name next to {path}")


def write_if_changed(path: str | Path, data: str | bytes) -> bool:
    """Write `data` (str as UTF-8) atomically unless `path` already holds exactly these bytes;
    whether it wrote. Re-rendering identical results then leaves files (and git) untouched."""
    path = Path(path)
    new = data.encode() if isinstance(data, str) else bytes(data)
    try:
        if path.stat().st_size == len(new) and path.read_bytes() == new:
            return False
    except FileNotFoundError:
        pass
    with atomic_write(path, binary=True) as f:
        f.write(new)
    return True


def check_writable(path: str | Path, *, folder: bool = False, option: str = "--out") -> None:
    """Raise a `GcdtError` unless `path` (a file, or with `folder` a folder to write files
    into) can be written: before hours of work, not after. Creates nothing.

    Missing folders on the way are fine (writers make them) when the nearest existing one is a
    writable folder. An existing read-only file is refused rather than replaced.
    """
    path = Path(path)
    hint = f"choose another {option}"
    if _exists(path):
        if path.is_dir() != folder:
            kind = "a folder" if path.is_dir() else "a file"
            wanted = "a folder" if folder else "a file"
            raise GcdtError(f"cannot write {path}: it is {kind}, not {wanted}; {hint}")
        if not os.access(path, os.W_OK | (os.X_OK if folder else 0)):
            raise GcdtError(f"cannot write {path}: it is not writable ({_why(path)}); {hint}")
        if folder:
            return
    parent = path.parent
    while not _exists(parent) and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise GcdtError(f"cannot write {path}: {parent} is not a folder; {hint}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise GcdtError(f"cannot write {path}: {parent} is not writable ({_why(parent)}); {hint}")


def _exists(path: Path) -> bool:
    """`path.exists()`, False where a folder on the way may not be searched: the walk up to the
    nearest existing folder then stops at that folder, which is refused as not writable."""
    try:
        return path.exists()
    except OSError:
        return False


def _why(path: Path) -> str:
    """Why `os.access` says no: a read-only file system or the permission bits."""
    try:
        if os.statvfs(path).f_flag & os.ST_RDONLY:
            return "read-only file system"
        mode = stat.filemode(path.stat().st_mode)
    except (OSError, AttributeError):  # statvfs is POSIX-only
        return "permission denied"
    return f"permission denied, mode {mode}"


def write_between_markers(path: str | Path, start: str, end: str, text: str) -> bool:
    """Replace what lies between the markers `start` and `end` in the text file `path` with
    `text` (written only if that changes the file); whether it wrote."""
    import re

    path = Path(path)
    old = path.read_text()
    if start not in old or end not in old:
        raise GcdtError(f"{path} lacks the markers {start} ... {end}")
    block = f"{start}\n{text}\n{end}"
    pattern = re.escape(start) + ".*?" + re.escape(end)
    return write_if_changed(path, re.sub(pattern, lambda _: block, old, flags=re.S))
