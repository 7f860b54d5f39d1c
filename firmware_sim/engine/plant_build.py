"""cffi build script for the C plant (``firmware_sim.engine._plant``); setup.py names it in ``cffi_modules``."""

import re
from pathlib import Path

from cffi import FFI

HERE = Path(__file__).resolve().parent


def cdef_from_header(path: Path) -> str:
    """plant.h as cffi's cdef wants it (the header stays the single definition): comments, the include
    guard and #includes removed, array sizes given by #define constants written out as numbers."""
    text = re.sub(r"/\*.*?\*/", "", path.read_text(), flags=re.S)
    lines = [ln for ln in text.splitlines()
             if not re.match(r"\s*#\s*(ifndef|endif|include|define\s+HILBENCH_PLANT_H)", ln)]
    text = "\n".join(lines)
    for name, value in re.findall(r"#define\s+(HB_\w+)\s+(\d+)", text):
        text = text.replace(f"[{name}]", f"[{value}]")
    return text


CDEF = cdef_from_header(HERE / "plant.h")

ffibuilder = FFI()
ffibuilder.cdef(CDEF)
ffibuilder.set_source(
    "hilbench.firmware_sim.engine._plant",
    '#include "plant.h"',
    sources=[str(Path("firmware_sim") / "engine" / "plant.c")],
    include_dirs=[str(HERE)],
    extra_compile_args=["-O3", "-std=c99", "-ffp-contract=off", "-fno-fast-math"],
    libraries=["m"],
)

if __name__ == "__main__":
    ffibuilder.compile(verbose=True)
