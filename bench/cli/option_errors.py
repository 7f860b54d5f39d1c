"""Errors in the words of the command line: a setting's name in a message becomes the option that sets it."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager


@contextmanager
def options_named(names: Iterable[str]) -> Iterator[None]:
    """A protocol's or the device settings' error starts with the parameter's name (``cutoff = 6000 Hz is
    outside ...``); on the command line it is the option: ``--cutoff 6000 Hz is outside ...``."""
    from hilbench.bench.errors import BenchError

    try:
        yield
    except BenchError as exc:
        text = str(exc)
        for name in sorted(names, key=len, reverse=True):
            if text.startswith(name) and text[len(name):len(name) + 1] in (" ", ""):
                rest = text[len(name):].removeprefix(" =")
                raise type(exc)("--" + name.replace("_", "-") + rest) from None
        raise
