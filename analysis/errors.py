"""Error types of the analysis layer."""

from hilbench.common.errors import InputError

#: Input that an analysis cannot use (too short, not exciting enough, missing channel...). It is the bottom layer's
#: :class:`~hilbench.common.errors.InputError` under the analysis layer's name, so that a refusal from the run-file
#: schema or a metric (``hilbench.common``) is caught wherever an analysis catches its own.
AnalysisError = InputError
