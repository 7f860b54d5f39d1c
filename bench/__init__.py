"""hilbench bench layer: measurement protocols, run files, campaigns, CLI and operator GUI.

``hilbench.bench`` uses ``drivers`` (device link) and ``analysis`` (offline methods); nothing imports ``bench``.
"""

# The compensated-reference protocol (position mode, docs/compensation.md) and the break-away probe live in modules
# of their own and add themselves to protocols.PROTOCOLS. Importing them here, where any import of a bench module
# starts, gives every user the whole table without protocols.py importing them (they import protocols.py: a cycle).
import hilbench.bench.acquisition.breakaway_probe  # noqa: E402,F401
import hilbench.bench.acquisition.compensation  # noqa: E402,F401
from hilbench import __version__

__all__ = ["__version__"]
