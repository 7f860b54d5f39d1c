"""hilbench bench layer: measurement protocols, run files, campaigns, CLI and operator GUI.

``bench`` uses ``drivers`` (device link) and ``analysis`` (offline methods); nothing imports ``bench``.
"""

__version__ = "0.1.0"
