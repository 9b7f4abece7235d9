"""Machine info recorded beside every benchmark and reproduction."""

from __future__ import annotations

import subprocess

import pytest

from gcdt import provenance


@pytest.mark.parametrize(
    ("flags", "native"),
    [
        ("fpu sse avx2 avx512f avx512_bf16", True),
        ("fpu avx512f amx_bf16 amx_tile", True),
        ("fpu sse avx2 avx512f avx512_vnni", False),  # bf16 would be emulated
        (None, None),  # no /proc/cpuinfo: unknown, not "no"
    ],
)
def test_cpu_bf16_reads_the_cpu_flags(monkeypatch, flags, native):
    monkeypatch.setattr(provenance, "_cpuinfo_field", lambda name: flags)
    assert provenance.cpu_bf16() is native


def test_machine_info_names_cpu_cores_and_torch():
    info = provenance.machine_info()
    assert set(info) >= {"cpu", "cpu_bf16", "cores", "python", "torch", "device"}
    assert info["cores"] >= 1 and info["cpu"]


def test_git_commit_is_dirty_for_code_changes_not_for_outputs(tmp_path, monkeypatch):
    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True)

    git("init", "-q")
    for name in ("gcdt.py", "results/run.json", "figures/fig.png"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("v1")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "init")
    monkeypatch.setattr(provenance, "REPO_ROOT", tmp_path)
    clean = provenance.git_commit()
    assert clean is not None and len(clean) == 40

    # A run rewrites its own outputs: still the same code.
    (tmp_path / "results/run.json").write_text("v2")
    (tmp_path / "figures/fig.png").write_text("v2")
    assert provenance.git_commit() == clean

    (tmp_path / "gcdt.py").write_text("v2")
    assert provenance.git_commit() == f"{clean}+dirty"
