"""The documentation as package data (docs/*.md): `hilbench docs [TOPIC]` lists and prints it."""
