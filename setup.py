"""Package layout and the C plant's cffi build (everything else is in pyproject.toml).

The repository keeps its top-level folders; the distribution installs them under one namespace:
bench/ -> hilbench.bench, drivers/ -> hilbench.drivers, firmware_sim/ -> hilbench.firmware_sim,
analysis/ -> hilbench.analysis. Nothing else lands at the top level of site-packages.
"""

from setuptools import find_packages, setup

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

setup(packages=packages, package_dir=package_dir,
      cffi_modules=["firmware_sim/engine/plant_build.py:ffibuilder",
                    "firmware/targets/host/core_build.py:ffibuilder"])
