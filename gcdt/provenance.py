"""What made an artifact: package versions, creation time, code revision."""

from __future__ import annotations

import datetime as dt
import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

from gcdt.paths import REPO_ROOT

#: The packages whose versions decide what a dataset or a run contains.
TRACKED_PACKAGES = ("gcdt", "numpy", "torch", "gymnasium", "pybullet", "panda-gym")


def package_versions(packages: tuple[str, ...] = TRACKED_PACKAGES) -> dict[str, str | None]:
    """Installed version of each package (None where it is not installed)."""
    versions: dict[str, str | None] = {}
    for name in packages:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def utc_now() -> str:
    """The current time, ISO 8601 in UTC, to the second."""
    return dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat()


def git_commit() -> str | None:
    """The repository's HEAD commit (with `+dirty` when the code has changes), or None.

    Changes under results/ and figures/ do not count: they are what a run writes, so a
    `make reproduce` would otherwise always call its own commit dirty."""
    try:
        head = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        code_only = ["--", ".", ":!results", ":!figures"]
        dirty = subprocess.run(
            [
                "git",
                "-C",
                str(REPO_ROOT),
                "status",
                "--porcelain",
                "--untracked-files=no",
                *code_only,
            ],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return f"{head}+dirty" if dirty else head


def _cpuinfo_field(name: str) -> str | None:
    """The first `name : value` of /proc/cpuinfo (Linux), or None."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.split(":", 1)[0].strip() == name:
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def cpu_model() -> str:
    """The CPU's model name (Linux), else what `platform` knows."""
    return _cpuinfo_field("model name") or platform.processor() or platform.machine()


def cpu_signature() -> str:
    """The CPU as run timings depend on it: its model and the vector instructions torch's
    kernels use here (e.g. "AMD EPYC, AVX2"). Virtual machines often report the same model
    for CPUs whose matmuls differ several-fold, AVX2 against AVX-512, so the model alone is
    not enough."""
    import torch  # only when asked, as in `machine_info`

    return f"{cpu_model()}, {torch.backends.cpu.get_cpu_capability()}"


def cpu_bf16() -> bool | None:
    """Whether the CPU computes bfloat16 natively (AVX512-BF16 or AMX); None if unknown.

    Without it bf16 autocast on CPU is emulated and several times slower than fp32."""
    flags = _cpuinfo_field("flags")
    return None if flags is None else bool({"avx512_bf16", "amx_bf16"} & set(flags.split()))


def numpy_kernels() -> list[str]:
    """The vector-kernel levels numpy dispatches to on this CPU (e.g. ["X86_V3", "X86_V4"]),
    those `NPY_DISABLE_CPU_FEATURES` switched off excluded.

    They decide the last bit of some functions' results (`np.arctan2`, float64 `np.exp`), so a
    scripted expert's actions, and the data it collects, are bit-identical only between CPUs
    with the same list."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]


def machine_info() -> dict[str, Any]:
    """Where a measurement ran: CPU model, cores, Python, torch and its device."""
    import torch  # only when asked: provenance is imported by code that needs no torch

    return {
        "cpu": cpu_model(),
        "cpu_bf16": cpu_bf16(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "device": "cuda" if torch.cuda.is_available() else "cpu",
        "gpu": torch.cuda.get_device_name() if torch.cuda.is_available() else None,
    }
