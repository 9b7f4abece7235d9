"""Machine info recorded beside every benchmark and reproduction."""

from __future__ import annotations

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
