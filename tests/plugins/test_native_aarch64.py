"""native-rnnpb's kernel on aarch64 (NEON) computes the x86 bits: cross-built, run under qemu.

``native_check.c`` trains a fixed batch (integer-generated data, so both
machines start from the same bits), recognizes and scores it, and prints
every result as float32 bits. It is compiled here for every instruction set
this CPU runs and cross-compiled for aarch64 with Debian's
``aarch64-linux-gnu-gcc``, then run under ``qemu-aarch64``; all outputs
must be equal. Skips, saying what is missing, where the cross compiler or
qemu-user is not installed (``.ci/run`` installs both when run as root:
``apt-get install gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user``).
"""

from __future__ import annotations

from pathlib import Path
import platform
import shutil
import subprocess

import pytest

HERE = Path(__file__).resolve().parent
HARNESS = HERE / "native_check.c"
#: the flags of plugins/iloci-native/pyproject.toml
FLAGS = ["-O3", "-fno-math-errno", "-ffp-contract=off", "-DILOCI_FP_CONTRACT_OFF"]
ISAS = {"portable": 1, "avx2": 2, "avx512": 3}


def _build(cc: str, out: Path) -> Path:
    subprocess.run([cc, *FLAGS, "-Wall", str(HARNESS), "-o", str(out), "-lm"], check=True,
                   capture_output=True, text=True)
    return out


def _run(cmd: list[str]) -> str:
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{cmd} failed: {done.stderr}"
    return done.stdout


@pytest.fixture(scope="module")
def x86_outputs(tmp_path_factory) -> dict[str, str]:
    pytest.importorskip("iloci_native", reason="native-rnnpb (plugins/iloci-native) not installed")
    if platform.machine() not in ("x86_64", "AMD64"):
        pytest.skip("the x86 side of the comparison needs an x86-64 machine")
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler")
    exe = _build(cc, tmp_path_factory.mktemp("x86") / "native_check")
    from iloci_native.native import native_isas
    return {isa: _run([str(exe), str(ISAS[isa])]) for isa in native_isas()}


def test_the_x86_paths_print_the_same_bits(x86_outputs):
    outs = set(x86_outputs.values())
    assert len(outs) == 1, "instruction sets differ: " + ", ".join(x86_outputs)
    assert len(next(iter(outs)).splitlines()) == 9


def test_aarch64_under_qemu_prints_the_x86_bits(x86_outputs, tmp_path):
    cross = shutil.which("aarch64-linux-gnu-gcc")
    qemu = shutil.which("qemu-aarch64") or shutil.which("qemu-aarch64-static")
    if cross is None or qemu is None:
        pytest.skip("needs aarch64-linux-gnu-gcc and qemu-aarch64 (apt-get install "
                    "gcc-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user); "
                    f"missing: {'the cross compiler' if cross is None else 'qemu-user'}")
    exe = _build(cross, tmp_path / "native_check_aarch64")
    got = _run([qemu, "-L", "/usr/aarch64-linux-gnu", str(exe), str(ISAS["portable"])])
    want = next(iter(x86_outputs.values()))
    for a, b in zip(got.splitlines(), want.splitlines()):
        assert a == b, f"aarch64 differs from x86 in {a.split()[0]}"
    assert len(got.splitlines()) == len(want.splitlines())
