"""hilbench drivers: wire protocol, links (serial, CAN) and the high-level Amplifier client.

``drivers`` never imports ``bench``, ``analysis`` or ``firmware_sim``; ``sim://`` starts the simulator
as a separate process.
"""
