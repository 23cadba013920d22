"""A log's stamps without a sidecar: a step for good is a jump, scatter is none, a skip is named.

References: stamps built from known cycle numbers, a known latency and known delays.
"""

import numpy as np
import pytest

from rts_scenario.radar.clock import RadarClock
from rts_scenario.recheck import counter_skip, stamp_jump

CLOCK = RadarClock(cycle_s=0.072, start_offset_s=0.0, latency_s=0.13, jitter_s=0.005,
                   counter_start=0)
CYCLES = np.arange(300)


def stamped(rng, mean_delay_s=0.008):
    """Stamps of a 72 ms radar whose host stamps each cycle late by an exponential delay."""
    return 1.7e9 + CLOCK.latency_s + CYCLES * CLOCK.cycle_s + rng.exponential(mean_delay_s,
                                                                               CYCLES.size)


@pytest.mark.parametrize("seed", range(12))
def test_stamps_scattering_beyond_the_profile_s_jitter_are_no_jump(seed):
    # A busy host delays its stamps by 8 ms on average (more than the profile's +-5 ms): the
    # median of 8 stamps now and then moves by more than the bound, read as a jump for good.
    assert stamp_jump(CYCLES, stamped(np.random.default_rng(seed)), CLOCK) is None


@pytest.mark.parametrize("seed", range(4))
def test_a_step_in_scattered_stamps_is_found_where_it_is_and_as_large(seed):
    t = stamped(np.random.default_rng(seed))
    t[150:] += 0.040  # the latency grew by 40 ms
    at, size = stamp_jump(CYCLES, t, CLOCK)
    assert abs(at - 150) <= 2
    assert size == pytest.approx(0.040, abs=0.004)


def test_a_counter_that_skips_ahead_is_a_skip_not_a_jump_of_the_stamps():
    # The counter steps by 1001 at cycle 100, the stamps keep their pace: numbered by the
    # counter, the stamps read 1000 cycles (72 s) early from there on.
    t = stamped(np.random.default_rng(0), mean_delay_s=0.001)
    numbers = CYCLES + np.where(CYCLES >= 100, 1000, 0)
    at, size = stamp_jump(numbers, t, CLOCK)
    assert at == 100 and size == pytest.approx(-72.0, abs=0.005)
    assert counter_skip(size, CLOCK, 65536) == 1000
    assert counter_skip(-size, CLOCK, 65536) == -1000  # back: a count that restarted
    # No whole number of cycles, or more than half of what the counter counts: the host's
    # clock (an hour is 72,000 cycles of a 50 ms radar).
    assert counter_skip(0.040, CLOCK, 65536) is None
    assert counter_skip(-36.0 - 0.030, CLOCK, 65536) is None
    fifty = RadarClock(cycle_s=0.05, start_offset_s=0.0, latency_s=0.0, counter_start=0)
    assert counter_skip(3600.0, fifty, 65536) is None
    assert counter_skip(-72.0, CLOCK, 256) is None  # beyond an 8-bit count's half
