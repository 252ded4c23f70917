"""Hardware abstraction layer: peripheral interfaces and their backends."""
