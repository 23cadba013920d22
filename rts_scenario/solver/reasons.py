"""Why a target could not be synthesized: one code per target."""

from __future__ import annotations

from enum import IntEnum


class Reason(IntEnum):
    """Per-target outcome of the weight solver; ``OK`` means feasible."""

    OK = 0
    OUTSIDE = 1
    NO_SOLUTION = 2
    DEGENERATE = 3
    SPLIT = 4
    NOT_CONVERGED = 5

    @property
    def description(self) -> str:
        """One sentence a test engineer can act on."""
        return _DESCRIPTIONS[self]


_DESCRIPTIONS = {
    Reason.OK: "feasible",
    Reason.OUTSIDE: "outside every quad of the rig",
    Reason.NO_SOLUTION: "no non-negative weights put the peak at this angle "
                        "(outside the region the quad can synthesize)",
    Reason.DEGENERATE: "the quad is degenerate (FEs share an azimuth or an elevation) and the "
                       "target is off the line it spans",
    Reason.SPLIT: "the echoes would split: the beamformer's global maximum is not at the set "
                  "angle, or a second peak the radar would report as another target lies "
                  "elsewhere (FE spacing too wide for this radar)",
    Reason.NOT_CONVERGED: "the iteration for this non-centro-symmetric array did not converge",
}
