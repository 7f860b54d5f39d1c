"""The firmware core's own unit tests (firmware/tests/test_core.c), compiled here with the host gcc and run
against the golden frames the Python codec wrote. Built twice: with hb_real = double (the default, under
AddressSanitizer and UBSan when available) and with -DHB_REAL_FLOAT (the single-precision FPU policy)."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SOURCES = [*sorted((ROOT / "firmware" / "core").glob("*.c")), ROOT / "firmware" / "tests" / "fake_hal.c",
           ROOT / "firmware" / "tests" / "test_core.c"]
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Wpedantic", "-Werror", "-Wconversion", "-Wno-sign-conversion",
         "-O1", "-g"]


def sanitizers(cc: str, tmp: Path) -> list[str]:
    """-fsanitize=address,undefined when this compiler can link it, else nothing."""
    probe = tmp / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    flags = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
    res = subprocess.run([cc, *flags, str(probe), "-o", str(tmp / "probe")], capture_output=True)
    return flags if res.returncode == 0 else []


@pytest.mark.parametrize("real", ["double", "float"])
def test_core_unit_tests_pass(tmp_path, real):
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler (install gcc)")
    exe = tmp_path / "test_core"
    extra = ["-DHB_REAL_FLOAT"] if real == "float" else sanitizers(cc, tmp_path)
    build = subprocess.run([cc, *FLAGS, *extra,
                            f"-I{ROOT / 'firmware' / 'core'}", f"-I{ROOT / 'firmware' / 'tests'}",
                            *map(str, SOURCES), "-lm", "-o", str(exe)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    res = subprocess.run([str(exe), str(ROOT / "tests" / "data" / "protocol")], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr
    last = res.stdout.strip().splitlines()[-1]
    checks = int(last.split()[0])
    assert last.endswith(" 0 failed") and checks > 250, last
