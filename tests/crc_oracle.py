"""An independent definition of CRC-16/XMODEM (crcmod, a dev dependency) that the codec's crc16 is tested against."""

from collections.abc import Callable

import crcmod

crc16_reference: Callable[[bytes], int] = crcmod.mkCrcFun(0x11021, initCrc=0, rev=False, xorOut=0)
"""CRC-16/XMODEM as defined by crcmod."""
