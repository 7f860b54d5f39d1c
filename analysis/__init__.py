"""hilbench analysis: identification, skeleton (ForceVib) analysis, AFRF and the residual loop.

Works on arrays and run files only; it never talks to a device. It simulates models with the C
engine in :mod:`hilbench.firmware_sim.engine.plant`.
"""
