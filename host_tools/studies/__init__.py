"""Studies over many runs: parameter sweeps, tuning, fault campaigns and the interrupt handling they share."""
