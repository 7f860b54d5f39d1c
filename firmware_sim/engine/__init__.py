"""The simulation engine: the C plant (plant.c, built with cffi) and its Python wrapper, the friction model
presets, and the slow drift laws. Used by the simulated devices and by the analysis; it never touches a device."""
