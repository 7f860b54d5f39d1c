from setuptools import setup

setup(cffi_modules=["firmware_sim/plant_build.py:ffibuilder"])
