"""The bottom layer: definitions every layer shares, and nothing else.

Units (axis and mode units), the run-file schema and its keys, the error metrics and their names, and the CAN
frame and buffer helpers live here, each with one owner. Every package (drivers, firmware_sim, analysis, bench)
may import ``hilbench.common``; ``hilbench.common`` imports nothing else of hilbench (only the standard library and
the chosen third-party packages). ``tests/import_contract.py`` enforces both rules.
"""
