"""A radar in a room: a static reflector it reports every cycle, whatever the RTS plays.

On a bench a wall, the RTS's housing or the coupling path between the FEs and the radar return
an echo at a fixed range and 0 m/s, which the radar reports alongside the played target and may
report stronger than a weak FE's echo. The simulated radar has no room; these helpers add the
reflector's detection to its cycles.

The noiseless simulated radar reports every detection at an infinite SNR; in the room every
detection's SNR follows the radar equation instead (its RCS over its range to the fourth, to an
arbitrary reference that keeps it within the SNR signal of the CAN messages), so that the
strongest detection is the one a real radar would report strongest.
"""

from dataclasses import replace

import numpy as np

# SNR of a 0 dBsm target at 1 m in the room (dB): keeps the shipped rigs' echoes and the
# reflectors within 0 to 127.5 dB, the SNR signal of the shipped classic CAN messages.
SNR_AT_1_M_DB = 100.0


def in_room(cycles, range_m, radial_velocity_mps, rcs_dbsm, az_deg=0.0, el_deg=0.0):
    """Return ``cycles`` with the reflector's detection added to each one that came back."""
    reflector = {"range_m": range_m, "radial_velocity_mps": radial_velocity_mps,
                 "az_deg": az_deg, "el_deg": el_deg, "rcs_dbsm": rcs_dbsm}
    out = []
    for cycle in cycles:
        if not cycle.complete:  # a cycle lost on the way stays lost
            out.append(cycle)
            continue
        values = {q: np.append(getattr(cycle, q), v) for q, v in reflector.items()}
        values["snr_db"] = (values["rcs_dbsm"] - 40.0 * np.log10(values["range_m"])
                            + SNR_AT_1_M_DB)
        out.append(replace(cycle, **values))
    return out


def with_reflector(measure, range_m, radial_velocity_mps, rcs_dbsm, az_deg=0.0, el_deg=0.0):
    """``measure`` (schedule in, cycles out) in a room with that reflector."""
    def measure_in_room(schedule):
        return in_room(measure(schedule), range_m, radial_velocity_mps, rcs_dbsm, az_deg,
                       el_deg)

    return measure_in_room
