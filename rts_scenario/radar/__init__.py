"""The radar under test: its profile (chirp, timing, array) and, later, the simulated radar."""

from .profile import RadarProfile

__all__ = ["RadarProfile"]
