"""A simulated radar running free behind a CAN interface that stamps with its own clock."""

from dataclasses import replace

import numpy as np

from rts_scenario.detections import Detections
from rts_scenario.radar.clock import RadarClock


def free_profile(radar, latency_cycles, jitter_s=0.005):
    """``radar`` running free (no counter start), ``latency_cycles`` of its cycle late."""
    clock = radar.radar_clock
    return replace(radar, clock=replace(clock, counter_start=None, jitter_s=jitter_s,
                                        latency_s=latency_cycles * clock.cycle_s))


def behind_own_clock(bench, offset_s, *, early=3, delivery_s=0.003, seed=7, ahead_s=None):
    """Make ``bench``'s simulated radar run free behind an interface with its own clock.

    Its cycle is ``offset_s`` along when each measurement's frames start; its ``early`` cycles
    measured before the first frame (nothing played) come first; the interface stamps every
    message with seconds since it was plugged in (1234.5 s at the frames' start; ``ahead_s``:
    the host's time plus that, a clock set from the host's once) and the host receives each up
    to ``delivery_s`` after it was stamped.
    """
    clock = bench.radar.radar_clock
    own = RadarClock(cycle_s=clock.cycle_s, start_offset_s=offset_s, latency_s=clock.latency_s,
                     jitter_s=clock.jitter_s, counter_start=811)
    bench.output.clock = own
    sink = bench.output._sink

    def switched_on_before(cycles):
        if cycles and cycles[0].cycle == 811:
            first = cycles[0]
            cycles = [*(Detections.empty(811 - k, first.t_s - k * own.cycle_s)
                        for k in range(early, 0, -1)), *cycles]
        sink(cycles)

    bench.output._sink = switched_on_before
    plugged_in_s = bench._scene_origin_s() - 1234.5 if ahead_s is None else -ahead_s
    bus = bench._publisher.bus
    send = bus.send

    def stamped_by_the_interface(msg, timeout=None):
        msg.timestamp -= plugged_in_s
        send(msg, timeout)

    bus.send = stamped_by_the_interface
    rng = np.random.default_rng(seed)
    bench.receiver.received_at = (
        lambda msg: msg.timestamp + plugged_in_s + rng.uniform(0.0, delivery_s))
