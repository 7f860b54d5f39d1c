"""hilbench bench layer: measurement protocols, run files, campaigns, CLI and operator GUI.

``hilbench.bench`` uses ``drivers`` (device link) and ``analysis`` (offline methods); nothing imports ``bench``.
"""

# Light on purpose: nothing here imports numpy or the acquisition layer, so that ``hilbench analyse`` starts its
# local cluster's host 0.03 s after its first line, not 0.15-0.2 s (bench.cli.main; the protocol table is completed
# by bench/acquisition/__init__.py).
from hilbench import __version__

__all__ = ["__version__"]
