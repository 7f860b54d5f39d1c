"""hilbench bench layer: measurement protocols, run files, campaigns, CLI and operator GUI.

``hilbench.bench`` uses ``drivers`` (device link) and ``analysis`` (offline methods); nothing imports ``bench``.
"""

# The compensated-reference protocol (position mode, docs/compensation.md) lives in its own module and adds itself to
# protocols.PROTOCOLS. Importing it here, where any import of a bench module starts, gives every user the whole
# table without protocols.py importing compensation.py (which imports protocols.py: a cycle).
import hilbench.bench.acquisition.compensation  # noqa: E402,F401
from hilbench import __version__

__all__ = ["__version__"]
