"""Control numerics: PID and cascade, references, filters, estimation (pure-Python per-sample code)."""
