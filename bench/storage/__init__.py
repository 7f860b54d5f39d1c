"""Files the bench writes and reads besides its own run files (which hilbench.common.runfile owns): foreign data
imported into run files, unit parsing for imports, and atomic output files."""
