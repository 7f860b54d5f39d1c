"""hilbench: hardware-in-the-loop test bench for DC motors with friction.

One import namespace over the repository's top-level folders (a package-dir mapping in setup.py):

- :mod:`hilbench.drivers`: the device interface, wire protocol and links;
- :mod:`hilbench.firmware_sim`: the simulated device and the C plant;
- :mod:`hilbench.bench`: protocols, run files, campaigns, the CLI and the GUI;
- :mod:`hilbench.analysis`: identification, skeleton, AFRF, models, residual loop, reproductions.
"""

__version__ = "0.2.0"
