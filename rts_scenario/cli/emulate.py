"""``rts-scenario emulate``: a simulated RTS and radar behind a real bench's interfaces."""

from __future__ import annotations

import argparse
import errno
import time
from typing import TYPE_CHECKING, Any

from .. import interrupts
from .calibrate import MAX_INJECT_GAIN_DB
from .common import EXIT_FAIL, EXIT_OK, check_can_interface, check_number, one_line

if TYPE_CHECKING:
    from ..rig import Rig


def _do_emulate(args: argparse.Namespace) -> int:
    import numpy as np

    from ..canbus.mapping import CanMapping
    from ..emulator import Emulator
    from ..errors import BusError, RtsError
    from ..radar.angle import estimator_names, estimator_problem
    from ..radar.profile import RadarProfile
    from ..radar.profile import preset_names as radar_presets
    from ..radar.simulate import ChannelErrors
    from ..rig import Rig
    from ..rig import preset_names as rig_presets
    from .common import check_fd_mapping, named_file, preset_or_file
    from .listen import _address

    host, port = _address(args.listen, "--listen")
    check_can_interface("--can-interface", args.can_interface, args.can_channel)
    given_channel = (f"--can-channel {args.can_channel}" if args.can_channel is not None
                     else "(no --can-channel: a private channel name)")
    if args.can_channel is None:
        args.can_channel = "rts-emulator"
    check_number("--seconds", args.seconds, low=0.001, high=86400.0)
    check_number("--wait", args.wait, low=0.001, high=86400.0)
    check_number("--inject-phase-deg", args.inject_phase_deg, low=0.0, high=180.0)
    check_number("--inject-gain-db", args.inject_gain_db, low=0.0, high=MAX_INJECT_GAIN_DB)
    if args.seed < 0:
        raise RtsError(f"--seed: must be >= 0, got {args.seed}")
    if args.estimator not in estimator_names():
        raise RtsError(f"--estimator: unknown estimator {args.estimator!r}; valid: "
                       f"{', '.join(estimator_names())}")
    mapping = named_file("--mapping", CanMapping.from_file, args.mapping) if args.mapping \
        else None
    check_fd_mapping(args.can_fd, args.mapping, mapping)
    rig = preset_or_file("--rig", args.rig, rig_presets(), Rig.preset, Rig.from_file,
                         ".rig.yaml")
    radar = preset_or_file("--radar", args.radar, radar_presets(), RadarProfile.preset,
                           RadarProfile.from_file, ".radar.yaml")
    if (problem := estimator_problem(args.estimator, radar.array)) is not None:
        raise RtsError(f"--estimator {args.estimator}: {problem}")
    # The channels' errors first, then the noise, from one generator: `calibrate --inject-*`
    # with the same --seed draws the same errors.
    rng = np.random.default_rng(args.seed)
    errors = ChannelErrors.random(rig.n_front_ends, rng, phase_deg=args.inject_phase_deg,
                                  gain_db=args.inject_gain_db)
    try:
        emulator = Emulator(rig, radar, host=host, port=port, can_interface=args.can_interface,
                            can_channel=args.can_channel, fidelity=args.fidelity,
                            estimator=args.estimator, noise=args.noise, rng=rng,
                            mapping=mapping, fd=args.can_fd, errors=errors)
    except BusError as exc:
        raise BusError(f"--can-interface {args.can_interface} {given_channel}: "
                       f"{one_line(exc)}") from None
    except OSError as exc:
        busy = ("; another emulate or RTS receiver listening on that port? stop it, or give "
                "another" if exc.errno == errno.EADDRINUSE else "")
        raise RtsError(f"--listen {args.listen}: cannot listen: {exc.strerror or exc}"
                       f"{busy}") from None
    emulator.start()
    bound_host, bound_port = emulator.address
    clock = radar.radar_clock
    print(f"listening on udp://{bound_host}:{bound_port}; radar {radar.name!r} measures every "
          f"{clock.cycle_s * 1e3:g} ms, reports {clock.latency_s * 1e3:g} ms later on "
          f"{args.can_interface}:{args.can_channel}", flush=True)
    if args.inject_phase_deg or args.inject_gain_db:
        _print_errors(errors, args.seed)
    if args.can_interface == "virtual":
        print("note: the virtual CAN bus is heard only inside this process; run SCENE in "
              "another one needs a shared interface (socketcan vcan, udp_multicast)", flush=True)
    # Until a stream starts (--wait), then until streams stop (--seconds without a datagram);
    # each run's counters as the next begins, the last's at the end.
    datagrams, quiet_since, quiet_s = 0, time.monotonic(), args.wait
    printed = 0
    refused = False
    try:
        while time.monotonic() - quiet_since < quiet_s:
            if emulator.receiver.stats.datagrams != datagrams:
                datagrams = emulator.receiver.stats.datagrams
                quiet_since, quiet_s = time.monotonic(), args.seconds
            for run in emulator.runs[printed:]:
                refused |= _print_run(run, rig)
                printed += 1
            time.sleep(0.01)
    except KeyboardInterrupt:
        interrupts.handled()
        interrupted = True
    else:
        interrupted = False
    finally:
        stats = emulator.stop()
    runs = stats["runs"]
    if not runs:
        print("stopped (Ctrl-C) before any stream arrived" if interrupted
              else f"no stream arrived within --wait {args.wait:g} s", flush=True)
        _print_run({"udp": stats["udp"], "radar": stats["radar"], "can_messages": 0}, rig)
    for run in runs[printed:]:
        refused |= _print_run(run, rig)
    if len(runs) > 1:
        print(f"{len(runs)} runs" + (": some refused (another rig)" if refused else ""),
              flush=True)
    # Nothing rehearsed, or a run refused for its rig: a script waiting on it must not read
    # that as a bench that worked.
    if refused or not (runs or interrupted):
        return EXIT_FAIL
    return EXIT_OK


def _print_errors(errors: Any, seed: int) -> None:
    """Print the injected channel errors as `calibrate` reports its offsets: against FE 0."""
    print(f"channel errors injected (--seed {seed}), relative to FE 0 as calibrate reports "
          f"them:", flush=True)
    print(f"{'FE':>3} {'phase deg':>10} {'gain dB':>8}", flush=True)
    for q in range(errors.phase_deg.size):
        phase = (errors.phase_deg[q] - errors.phase_deg[0] + 180.0) % 360.0 - 180.0
        print(f"{q:>3} {phase:>10.2f} {errors.gain_db[q] - errors.gain_db[0]:>8.3f}",
              flush=True)


def _print_run(run: dict[str, Any], rig: Rig) -> bool:
    """Print a run's counters (``run N:`` before each line); return whether it was refused."""
    udp, measured = run["udp"], run["radar"]
    head = f"run {run['run']}: " if "run" in run else ""
    print(f"{head}rts: {udp['frames_applied']} frames applied, {udp['datagrams']} datagrams, "
          f"{udp['lost_frames']} frames lost, {udp['corrupted']} corrupted, "
          f"{udp['malformed']} malformed"
          + (f", {udp['stale_frames']} frames came too late (after a newer one: not applied)"
             if udp.get("stale_frames") else ""), flush=True)
    if udp["other_rig"]:
        print(f"{head}error: {udp['other_rig']} datagrams name FEs that are no quad of rig "
              f"{rig.name!r} ({rig.rows} rows of {rig.columns} FEs): the run's rig is another; "
              f"not played", flush=True)
    if udp["malformed"] > udp["other_rig"]:
        print(f"{head}note: malformed datagrams are not played: a damaged datagram, or entries "
              f"naming a channel beyond 0..3", flush=True)
    print(f"{head}radar: {measured['cycles']} cycles measured, {measured['published']} "
          f"published ({measured['detections']} detections, {run['can_messages']} CAN "
          f"messages), worst {measured['worst_late_ms']} ms behind its clock", flush=True)
    return bool(udp["other_rig"])


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``emulate`` subcommand."""
    parser = subparsers.add_parser(
        "emulate", help="a simulated RTS (UDP in) and radar (CAN out) for bench rehearsals",
        parents=parents,
        description="Receive the schedule stream like an RTS (udp-protocol.md), hold each frame "
                    "until the next, and run the simulated radar on its own clock in real time "
                    "(the profile's clock: cycle, offset, latency, jitter, counter), publishing "
                    "its detections on CAN. Run `rts-scenario run SCENE --output "
                    "udp://HOST:PORT --can-interface I --can-channel C` against it. Waits up to "
                    "--wait for the first datagram, then stops after --seconds without one, or "
                    "on Ctrl-C.",
    )
    parser.add_argument("--listen", required=True, metavar="udp://HOST:PORT",
                        help="where the RTS listens (port 0: any free port)")
    parser.add_argument("--rig", required=True, help="rig preset or *.rig.yaml")
    parser.add_argument("--radar", required=True, help="radar profile or *.radar.yaml")
    parser.add_argument("--can-interface", default="virtual")
    parser.add_argument("--can-channel", default=None,
                        help="CAN channel (default rts-emulator; udp_multicast: a multicast "
                             "group address, e.g. 239.74.163.2)")
    parser.add_argument("--can-fd", action="store_true", help="CAN FD detection messages")
    parser.add_argument("--mapping", default=None,
                        help="*.mapping.yaml: speak a third-party radar's DBC (default: "
                             "rts-scenario's messages)")
    parser.add_argument("--fidelity", default="analytic", choices=["analytic", "adc"])
    parser.add_argument("--estimator", default="bartlett",
                        help="the radar's angle estimator (default bartlett)")
    parser.add_argument("--noise", action="store_true", help="thermal noise")
    parser.add_argument("--inject-phase-deg", type=float, default=0.0,
                        help="random phase errors of the RTS channels within +-this (0..180): "
                             "an uncalibrated RTS to rehearse `calibrate` on")
    parser.add_argument("--inject-gain-db", type=float, default=0.0,
                        help="random gain errors of the RTS channels within +-this "
                             f"(0..{MAX_INJECT_GAIN_DB:g})")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the injected errors and the noise (>= 0)")
    parser.add_argument("--seconds", type=float, default=10.0,
                        help="once a stream came, stop after this long without datagrams "
                             "(default 10)")
    parser.add_argument("--wait", type=float, default=600.0,
                        help="stop if no stream comes within this long (default 600)")
    parser.set_defaults(handler=_do_emulate)
