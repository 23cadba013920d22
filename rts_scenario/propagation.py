"""Free-space propagation: the speed of light in vacuum."""

C0_MPS = 299_792_458.0
"""Speed of light in vacuum, m/s."""
