"""The pyserial backend (real ports, any pyserial URL) and the sim:// URL handler.

Kept import-light on purpose: pyserial imports ``hal.serial.protocol_<scheme>`` modules through
this package when it is listed in ``serial.protocol_handler_packages``, so nothing is imported here.
"""
