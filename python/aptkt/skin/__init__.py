"""The multi-modal skin: protocol parser and encoder, patch configuration, skin sources,
recordings.

Sources: :class:`SerialSkin` (USB adapter), :class:`TsuSkin` (UDP), and any subclass of
:class:`SkinSourceBase` (the simulator's). All implement :class:`SkinSource`.
"""

from aptkt.skin.base import SkinSource
from aptkt.skin.config import CellConfig, ForceCalibration, PatchConfig, default_patch, load_patch
from aptkt.skin.protocol import (
    PACKET_LEN,
    PACKET_TYPES,
    RAW_FIELDS,
    RAW_RANGES,
    SCALE,
    StreamParser,
    encode_packet,
    encode_sensor_packets,
    quantize,
)
from aptkt.skin.samples import Recording, SkinSamples
from aptkt.skin.serial_skin import SerialSkin
from aptkt.skin.source import SkinSourceBase
from aptkt.skin.tsu import TsuSkin

__all__ = [
    "SkinSource",
    "SkinSourceBase",
    "SerialSkin",
    "TsuSkin",
    "SkinSamples",
    "Recording",
    "StreamParser",
    "quantize",
    "encode_sensor_packets",
    "encode_packet",
    "PACKET_LEN",
    "PACKET_TYPES",
    "RAW_FIELDS",
    "RAW_RANGES",
    "SCALE",
    "PatchConfig",
    "CellConfig",
    "ForceCalibration",
    "load_patch",
    "default_patch",
]
