"""Modeled response vectors of the rig's FEs on the radar's virtual array (DESIGN.md 5.5b).

On the bench the FEs are about 1 m away, often inside the radar's near field, and each has its
own receive and transmit antenna. The echo of FE q reaches virtual element ``v = t * n_rx + r``
(TX t, RX r) along the spherical legs ``d_up = |TX_t - FE_q,rx|`` and
``d_down = |FE_q,tx - RX_r|``, so the radar sees the vector::

    r_q[v] = (D_q / d_up) (D_q / d_down) exp(-j k (d_up + d_down))

(free-space amplitude per leg relative to the FE's distance ``D_q``, about 1), not the plane-wave
steering vector ``a(u_q, s_q)_v = exp(+j k (y_v u_q + z_v s_q))``. A plane wave from ``(u, s)``
shortens both legs by ``u . p``, so far away ``r_q`` is proportional to ``a(u_q, s_q)``: the sign
conventions agree. The phase common to all elements is referenced to the virtual array's
centroid: the mean phase over the elements is removed, which makes a far FE's vector exactly its
steering vector. (The rig's phase calibration makes the channels coherent in that sense.)

The wavenumber ``k`` is the virtual array's, the one the radar's estimator steers with: the
wavelength at the centre of the sampled sweep. An echo's phase across the elements is governed by
the frequency the radar receives at that instant, which is lower by ``S T`` (chirp slope times
the echo's total delay); for a target at range R that is ``S 2R / c0``, a relative change of
about ``1e-4`` at 40 m on a 40 MHz/us chirp, which the model leaves out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .arrays import Antennas, VirtualArray
from .errors import SolverError
from .rig import Rig

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


@dataclass(frozen=True, eq=False)
class FrontEndModel:
    """How the solver models the FEs' echoes: the radar's physical antennas.

    Parameters
    ----------
    antennas : Antennas
        The radar's TX and RX phase centres relative to its reference point (the point the
        rig's FE angles and distances are measured from).
    """

    antennas: Antennas

    @property
    def key(self) -> tuple[Any, ...]:
        """Hashable identity of the antenna positions (the rig's part is in `rig_key`)."""
        a = self.antennas
        return ("front-end model", a.tx_y_m.tobytes(), a.tx_z_m.tobytes(), a.rx_y_m.tobytes(),
                a.rx_z_m.tobytes())

    @staticmethod
    def rig_key(rig: Rig) -> tuple[Any, ...]:
        """Return the rig's values the modeled responses depend on beyond its FE angles."""
        return (rig.distance_m.tobytes(), rig.rx_offset_m.tobytes(), rig.tx_offset_m.tobytes())

    def check(self, array: VirtualArray) -> None:
        """Raise `SolverError` unless ``array`` is these antennas' virtual array (TX-major)."""
        a = self.antennas
        y = (a.tx_y_m[:, None] + a.rx_y_m[None, :]).ravel()
        z = (a.tx_z_m[:, None] + a.rx_z_m[None, :]).ravel()
        tol = 1e-9 * array.wavelength_m
        if y.size != array.n_elements or not (
            np.allclose(y - y.mean(), array.y_m, rtol=0.0, atol=tol)
            and np.allclose(z - z.mean(), array.z_m, rtol=0.0, atol=tol)
        ):
            raise SolverError(
                f"front-end model: antennas {a.name!r} ({a.n_tx} TX x {a.n_rx} RX) do not make "
                f"the virtual array {array.name!r} ({array.n_elements} elements); the model and "
                f"the array must come from the same radar profile"
            )

    def vectors(self, rig: Rig, fes: NDArray[np.int64], array: VirtualArray) -> ComplexArray:
        """Response vectors of FEs ``fes`` on ``array``, shape ``(M, len(fes))``.

        Element order is the array's (TX-major); each column's mean phase is 0.
        """
        self.check(array)
        a = self.antennas
        az, el = np.radians(rig.az_deg[fes]), np.radians(rig.el_deg[fes])
        distance = rig.distance_m[fes]
        line = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        e_az = np.column_stack([-np.sin(az), np.cos(az), np.zeros_like(az)])
        e_el = np.column_stack([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)])

        def legs(offset: FloatArray, y: FloatArray, z: FloatArray) -> FloatArray:
            """Distance from each FE antenna to each radar antenna, less the FE's distance.

            Computed as ``(|p|^2 - D^2) / (|p| + D)`` with p relative to the radar antenna, so
            that the millimetre differences keep their precision next to the metre.
            """
            # FE antenna relative to its FE's nominal point, then to each radar antenna.
            rel = offset[:, :1] * e_az + offset[:, 1:] * e_el  # (Q, 3)
            radar = np.column_stack([np.zeros_like(y), y, z])  # (A, 3)
            delta = rel[:, None, :] - radar[None, :, :]  # (Q, A, 3)
            # |D l + delta|^2 - D^2 = 2 D l.delta + |delta|^2
            excess = 2.0 * distance[:, None] * np.einsum("qk,qak->qa", line, delta) + np.einsum(
                "qak,qak->qa", delta, delta)
            length = np.sqrt(distance[:, None] ** 2 + excess)
            return excess / (length + distance[:, None])

        up = legs(rig.rx_offset_m[fes], a.tx_y_m, a.tx_z_m)  # (Q, T)
        down = legs(rig.tx_offset_m[fes], a.rx_y_m, a.rx_z_m)  # (Q, R)
        excess = (up[:, :, None] + down[:, None, :]).reshape(len(fes), -1)  # (Q, M)
        phase = -array.wavenumber_rad_per_m * excess
        phase -= phase.mean(axis=1, keepdims=True)
        d = distance[:, None]
        level = ((d / (d + up))[:, :, None] * (d / (d + down))[:, None, :]).reshape(len(fes), -1)
        return np.ascontiguousarray((level * np.exp(1j * phase)).T)


__all__ = ["FrontEndModel"]
