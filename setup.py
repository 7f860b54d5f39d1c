"""Package layout and the C plant's cffi build (everything else is in pyproject.toml).

The repository keeps its top-level folders; the distribution installs them under one namespace:
bench/ -> hilbench.bench, drivers/ -> hilbench.drivers, firmware_sim/ -> hilbench.firmware_sim,
analysis/ -> hilbench.analysis. Nothing else lands at the top level of site-packages.
"""

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

SUBPACKAGES = ("bench", "drivers", "firmware_sim", "analysis")

package_dir = {"hilbench": "hilbench"}
# hilbench/common: the bottom layer of shared definitions (units, run-file schema, metrics, CAN helpers)
packages = ["hilbench"] + [f"hilbench.{name}" for name in find_packages("hilbench")]
for sub in SUBPACKAGES:
    package_dir[f"hilbench.{sub}"] = sub
    packages += [f"hilbench.{sub}"] + [f"hilbench.{sub}.{name}" for name in find_packages(sub)]

# The examples the docs tell a user to run (examples/*.toml, *.py) ship as hilbench.examples; `hilbench examples`
# copies them out of an installed wheel.
package_dir["hilbench.examples"] = "examples"
packages.append("hilbench.examples")

# The docs (docs/*.md) ship as hilbench.docs, data only: `hilbench docs [TOPIC]` lists and prints them. The
# scripts that draw their figures (docs/make_*.py) stay in the repository.
package_dir["hilbench.docs"] = "docs"
packages.append("hilbench.docs")


class BuildPy(build_py):
    def find_package_modules(self, package, package_dir):
        return [m for m in super().find_package_modules(package, package_dir)
                if m[0] != "hilbench.docs" or m[1] == "__init__"]


setup(packages=packages, package_dir=package_dir, cmdclass={"build_py": BuildPy},
      cffi_modules=["firmware_sim/engine/plant_build.py:ffibuilder",
                    "firmware/targets/host/core_build.py:ffibuilder"])
