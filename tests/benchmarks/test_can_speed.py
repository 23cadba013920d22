"""Detections through CAN to the checker: messages per second, encode -> bus -> decode -> check.

Run: ``pytest tests/benchmarks/test_can_speed.py -s``. The in-process path (what a run with the
simulated radar uses: cycles published in batches on a `ListenerBus`, straight to the receiver)
against python-can's virtual bus with a reader (a copy of each message and a queue), in
alternating rounds of the same run (`rts_scenario.perf.can_rate`).
"""

from rts_scenario import perf


def test_can_encode_bus_decode_check(benchmark):
    benchmark.group = "CAN: 1200 frames x 8 detections, encode -> bus -> decode -> check"
    figure = benchmark.pedantic(perf.can_rate, rounds=1, iterations=1)
    print("\n" + figure.line())
    benchmark.extra_info.update(messages_per_s=figure.value,
                                virtual_bus_messages_per_s=figure.comparison_value)
    assert figure.met
