"""Example files that ship with hilbench (campaign TOML, simulator configs, scripts): installed as
``hilbench.examples``; ``hilbench examples -o DIR`` copies them where the docs' commands find them."""
