"""Large 12 TX x 16 RX virtual arrays for the split-check tests and benchmarks.

Positions are given in half wavelengths at 77 GHz (1 GHz chirp); RX sit in a row at z = 0.
"""

import numpy as np

import rts_scenario as rs
from rts_scenario.arrays import PAPER_BANDWIDTH_HZ, PAPER_FC_HZ, wavelength_from_chirp

WAVELENGTH_M = wavelength_from_chirp(PAPER_FC_HZ, PAPER_BANDWIDTH_HZ)
HALF_M = WAVELENGTH_M / 2


def cascade_like(tx_y, tx_z, rx_y, name="cascade-like") -> rs.VirtualArray:
    """Virtual array of TX (y, z) and RX (y) positions given in half wavelengths."""
    tx_y, tx_z, rx_y = (np.asarray(v, dtype=float) * HALF_M for v in (tx_y, tx_z, rx_y))
    return rs.VirtualArray.from_tx_rx(tx_y, tx_z, rx_y, np.zeros(rx_y.size), fc_hz=PAPER_FC_HZ,
                                      bandwidth_hz=PAPER_BANDWIDTH_HZ, name=name)


def ti_cascade() -> rs.VirtualArray:
    """TI's four-chip cascade (MMWCAS-RF-EVM): 9 TX in azimuth, 3 raised; 16.6 cm aperture."""
    return cascade_like([11, 10, 9, 32, 28, 24, 20, 16, 12, 8, 4, 0],
                        [6, 4, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0],
                        [*range(11, 15), *range(50, 54), *range(46, 50), *range(0, 4)],
                        name="ti-cascade")


# A compact cascade-like layout (3.6 cm): 16 RX in a row lambda/2 apart, 12 TX, three of them
# raised by 1.5 and 3 wavelengths. The raised rows are a multiple of 1.5 lambda apart, so |B|
# repeats every 2/3 in s: a grating lobe inside the radar's field of view.
COMPACT_TX_Y = [2, 0, 5, 6, 11, 1, 11, 8, 5, 4, 8, 5]
COMPACT_TX_Z = [0, 0, 0, 0, 0, 6, 0, 0, 6, 0, 0, 3]
COMPACT_RX_Y = list(range(8, 24))


def compact_cascade() -> rs.VirtualArray:
    """The compact cascade-like layout above."""
    return cascade_like(COMPACT_TX_Y, COMPACT_TX_Z, COMPACT_RX_Y, name="compact-cascade")
