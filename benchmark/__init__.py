"""Privacy Lens Bench runner: scenes, metrics, the run loop, reports and the CLI (`python -m benchmark`)."""
