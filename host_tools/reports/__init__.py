"""Reports of a run: metrics, plots, telemetry CSV, the run's output files and the doc figures."""
