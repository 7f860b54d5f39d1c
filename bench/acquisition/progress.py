"""A terminal progress bar with ETA for runs (tqdm), fed by :class:`bench.acquisition.runner.Progress` events."""

from __future__ import annotations

import sys

from tqdm import tqdm


class ProgressBar:
    """Context manager; pass :meth:`update` as a run's ``progress`` callback."""

    def __init__(self, disable: bool = False, desc: str = "run"):
        self._bar: tqdm | None = None
        self._disable = disable
        self._desc = desc

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, p) -> None:
        if self._bar is None:
            self._bar = tqdm(total=p.total, unit="sample", unit_scale=True, desc=self._desc,
                             disable=True if self._disable else None, file=sys.stderr,
                             dynamic_ncols=True, mininterval=0.5)
        if p.n_segments > 1:
            self._bar.set_postfix_str(f"step {p.segment + 1}/{p.n_segments}", refresh=False)
        self._bar.update(p.done - self._bar.n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
