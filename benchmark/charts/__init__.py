"""Charts of a run, rendered from its results."""
