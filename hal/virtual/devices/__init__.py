"""Device models of the virtual bench: AK60-6 driver, BNO08x (UART-RVC), output encoder, telemetry sink."""

from hal.virtual.devices.ak60 import Ak60, Ak60Stats, DriveMode
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.bno08x import BANNER_LINES, Bno08x, Bno08xConfig
from hal.virtual.devices.encoder import EncoderMount
from hal.virtual.devices.plant_view import PlantView
from hal.virtual.devices.sink import ByteSink
from hal.virtual.devices.world import NEVER, Link, World

__all__ = [
    "BANNER_LINES", "NEVER", "Ak60", "Ak60Config", "Ak60Stats", "Bno08x", "Bno08xConfig", "ByteSink",
    "DriveMode", "EncoderMount", "Link", "PlantView", "World",
]
