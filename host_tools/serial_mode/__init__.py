"""Serial mode: the firmware on real ports (or sim://), its host watchdog, link and timing checks, and its report."""
