"""Acquisition: protocols and their excitations, the runner that streams them to a device and records the run,
campaigns of runs, compensated runs, and the device settings shared by the CLI and the GUI."""

# The compensated-reference protocol (position mode, docs/compensation.md) and the break-away probe live in modules
# of their own and add themselves to protocols.PROTOCOLS. Importing them here, where any import of an acquisition
# module starts (protocols.py's own included), gives every user the whole table without protocols.py importing them
# (they import protocols.py: a cycle). Not in bench/__init__.py: every bench module would then import numpy and the
# acquisition layer (0.13 s), the CLI's included before ``hilbench analyse`` starts its cluster.
import hilbench.bench.acquisition.breakaway_probe  # noqa: E402,F401
import hilbench.bench.acquisition.compensation  # noqa: E402,F401
