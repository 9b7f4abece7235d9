"""Artifact storage a cluster's nodes share without a shared filesystem: a URI (fsspec).

With `gcdt sweep --storage URI` (`s3://bucket/gcdt`, `gs://…`, `file:///scratch/gcdt`), a
node that needs a dataset, a TQC+HER agent or a training checkpoint first looks for it under
the URI and downloads it into its own artifacts folder; one it makes is uploaded there. Each
node keeps its local copies (`$GCDT_ARTIFACTS` on that node); nothing needs the same path on
every node. Without a URI each node makes what it needs itself (artifacts are content-keyed
and deterministic: two nodes make the same file).

Files are uploaded under a temporary name and moved into place, the file that marks an
artifact complete last; downloads land in a temp file renamed into place. A reader therefore
never takes half an artifact for a whole one. Two nodes making the same artifact at once both
upload the same bytes.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcdt.errors import GcdtError

#: Environment variable naming the storage URI inside a run (set by the sweep's tasks).
STORAGE_ENV = "GCDT_STORAGE"


@dataclass(frozen=True)
class ArtifactStorage:
    """The artifact tree (what `<artifacts>/grid/` holds) under a storage URI."""

    uri: str

    def _fs(self) -> tuple[Any, str]:
        import fsspec

        try:
            fs, root = fsspec.core.url_to_fs(self.uri)
        except (ImportError, ValueError) as err:  # unknown protocol, or its package missing
            raise GcdtError(
                f"cannot use storage URI {self.uri!r} ({_first_line(err)}): give a URI fsspec "
                "knows (file:///path, s3://bucket/path with s3fs installed, ...)"
            ) from None
        return fs, root.rstrip("/")

    def check_writable(self) -> None:
        """Raise a `GcdtError` unless a file can be written (and removed) under the URI;
        leaves nothing behind."""
        fs, root = self._fs()
        probe = f"{root}/.gcdt-write-check-{secrets.token_hex(4)}"
        try:
            if "file" in fs.protocol:  # a local folder is made, as the artifacts folder is
                fs.makedirs(root, exist_ok=True)
            fs.pipe_file(probe, b"")
            fs.rm_file(probe)
        except Exception as err:  # any backend's refusal: permission, missing bucket, ...
            raise GcdtError(
                f"cannot write storage URI {self.uri!r} ({_first_line(err)}): give a "
                "writable location, or leave out --storage"
            ) from None

    def fetch(self, local_root: Path, names: Sequence[str]) -> bool:
        """Download artifact `names` (paths relative to the tree; the last one marks it
        complete) into `local_root`; False, downloading nothing, if it is not complete there.
        Other names missing there are skipped (files an artifact may lack)."""
        fs, root = self._fs()
        if not fs.exists(f"{root}/{names[-1]}"):
            return False
        for name in names:
            if name != names[-1] and not fs.exists(f"{root}/{name}"):
                continue
            target = local_root / name
            target.parent.mkdir(parents=True, exist_ok=True)
            tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.tmp")
            try:
                fs.get_file(f"{root}/{name}", str(tmp))
                os.replace(tmp, target)
            finally:
                tmp.unlink(missing_ok=True)
        return True

    def publish(self, local_root: Path, names: Sequence[str]) -> None:
        """Upload `names` from `local_root`, each under a temp name moved into place, the last
        (the artifact's completion mark) last."""
        fs, root = self._fs()
        for name in names:
            target = f"{root}/{name}"
            tmp = f"{target}.{secrets.token_hex(4)}.tmp"
            fs.makedirs(target.rsplit("/", 1)[0], exist_ok=True)
            fs.put_file(str(local_root / name), tmp)
            fs.mv(tmp, target)


def run_storage() -> ArtifactStorage | None:
    """The storage of the run in progress (`$GCDT_STORAGE`), or None (node-local artifacts)."""
    uri = os.environ.get(STORAGE_ENV)
    return ArtifactStorage(uri) if uri else None


def _first_line(err: BaseException) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__
