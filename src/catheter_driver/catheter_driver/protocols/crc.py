"""The checksums the rig's protocols use, computed bitwise (frames are a few bytes long)."""

from __future__ import annotations


def crc16_a001(data: bytes, init: int = 0xFFFF) -> int:
    """CRC-16 with the reflected polynomial 0xA001 (0x8005), init 0xFFFF, no final XOR.

    The same register as CRC-16/MODBUS (check value of ``b"123456789"`` is 0x4B37); Keller
    and Modbus differ only in which byte they send first.
    """
    crc = init
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def crc8_07(data: bytes, init: int = 0x00) -> int:
    """CRC-8 with polynomial 0x07, init 0x00, no reflection, no final XOR (CRC-8/SMBUS).

    Check value of ``b"123456789"`` is 0xF4.
    """
    crc = init
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc
