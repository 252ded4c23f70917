"""The in-process virtual MCU (byte-timed UARTs, encoder timer, SysTick, pins) and the world wired to it."""
