"""Acquisition: protocols and their excitations, the runner that streams them to a device and records the run,
campaigns of runs, compensated runs, and the device settings shared by the CLI and the GUI."""
