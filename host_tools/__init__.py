"""Host-side tools: the `pafp` command line."""
