"""Checksums of a radar's messages, in the schemes a mapping names (docs/can-mapping.md).

``crc32-low-byte`` (rts-scenario's own): the low 8 bits of the CRC-32 of the message's other
bytes, in order. ``crc8-sae-j1850``: the CRC-8 SAE J1850 (polynomial 0x1D, initial value and
final XOR 0xFF) of the other bytes, in order. ``autosar-e2e-p2`` and ``autosar-e2e-p5``: the
AUTOSAR end-to-end profiles' CRCs with the message's data ID, as cantools computes them
(`cantools.autosar.end_to_end`): profile 2's CRC-8 (polynomial 0x2F) in byte 0 over bytes 1 on
and the data ID (from a DataIDList of 16 by the counter in byte 1's low nibble, or one), profile
5's CRC-16 in bytes 0 and 1 (low byte first) over bytes 2 on and the data ID.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable

import cantools
from cantools.autosar.end_to_end import compute_profile2_crc, compute_profile5_crc
from crccheck.crc import Crc8SaeJ1850

from .mapping import Checksum, checksum_bytes

# Fill a message's checksum in place; tell whether a message's checksum is right.
Seal = Callable[[bytearray], None]
Verify = Callable[[bytes | bytearray], bool]


def crc32_low_byte(data: bytes | bytearray, position: int) -> int:
    """Low 8 bits of the CRC-32 of the payload without its checksum byte."""
    crc = zlib.crc32(data[:position])
    if position + 1 < len(data):  # (most often the checksum is the last byte)
        crc = zlib.crc32(data[position + 1 :], crc)
    return crc & 0xFF


def crc8_sae_j1850(data: bytes | bytearray, position: int) -> int:
    """CRC-8 SAE J1850 of the payload without its checksum byte."""
    return int(Crc8SaeJ1850.calc(bytes(data[:position]) + bytes(data[position + 1 :])))


def _e2e_p2(data_id: int | tuple[int, ...]) -> Callable[[bytes | bytearray], int]:
    def crc(data: bytes | bytearray) -> int:
        ident = data_id[data[1] & 0x0F] if isinstance(data_id, tuple) else data_id
        value = compute_profile2_crc(bytes(data), ident)
        assert value is not None  # the mapping checked the message's length
        return value
    return crc


def _e2e_p5(data_id: int) -> Callable[[bytes | bytearray], int]:
    def crc(data: bytes | bytearray) -> int:
        value = compute_profile5_crc(bytes(data), data_id)
        assert value is not None  # the mapping checked the message's length
        return value
    return crc


def checksum_of(message: cantools.database.can.Message,
                spec: Checksum | None) -> tuple[Seal, Verify] | None:
    """Return how to fill and check a message's checksum, None if it carries none."""
    if spec is None or spec.signal not in {sg.name for sg in message.signals}:
        return None
    placed = checksum_bytes(message, spec)
    assert placed is not None  # the mapping checked it
    position, size = placed
    if spec.scheme in ("crc32-low-byte", "crc8-sae-j1850"):
        byte = crc32_low_byte if spec.scheme == "crc32-low-byte" else crc8_sae_j1850

        def seal(data: bytearray) -> None:
            data[position] = byte(data, position)

        def verify(data: bytes | bytearray) -> bool:
            return len(data) > position and data[position] == byte(data, position)

        return seal, verify
    data_id = spec.data_id_of(message.name)
    assert data_id is not None  # the mapping checked it
    if spec.scheme == "autosar-e2e-p2":
        e2e = _e2e_p2(data_id)
    else:
        assert isinstance(data_id, int)
        e2e = _e2e_p5(data_id)
    length = message.length

    def seal_e2e(data: bytearray) -> None:
        data[:size] = e2e(data).to_bytes(size, "little")

    def verify_e2e(data: bytes | bytearray) -> bool:
        return (len(data) >= length
                and int.from_bytes(data[:size], "little") == e2e(data[:length]))

    return seal_e2e, verify_e2e
