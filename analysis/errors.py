"""Error types of the analysis layer."""


class AnalysisError(ValueError):
    """Input that an analysis cannot use (too short, not exciting enough, missing channel...)."""
