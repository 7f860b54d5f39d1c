"""Errors the bench layer raises for bad user input; the CLI prints them as one line."""


class BenchError(Exception):
    """A user-facing error: bad file, bad parameter, bad campaign. The message is one line."""


class AnalyseError(BenchError):
    """A campaign folder or an option that ``hilbench analyse`` cannot analyse; one line."""
