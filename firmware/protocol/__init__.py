"""Wire codecs shared by firmware, device models and host tools (stdlib + crcmod only)."""
