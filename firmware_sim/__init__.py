"""hilbench simulated amplifier: the C plant (cffi) and the firmware that serves the wire protocol.

A peer on the wire: it may import ``hilbench.drivers.protocol`` but never ``bench`` or ``analysis``.
"""
