"""hilbench bench layer: measurement protocols, run files, campaigns, CLI and operator GUI.

``hilbench.bench`` uses ``drivers`` (device link) and ``analysis`` (offline methods); nothing imports ``bench``.
"""

from hilbench import __version__

__all__ = ["__version__"]
