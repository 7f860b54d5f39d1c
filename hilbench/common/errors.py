"""The error every layer raises for input it cannot use."""


class InputError(ValueError):
    """Input that cannot be used as given (a run file that breaks the schema, a constant reference signal for an
    NRMSE, a record an analysis cannot identify on...): the message says what and why, in one line. The analysis
    layer calls it ``AnalysisError``; the CLI turns it into ``error: ...`` and exit 2."""
