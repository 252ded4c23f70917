"""Wire codecs shared by firmware, device models and host tools (stdlib only)."""
