"""``rts-scenario rts-listen``: the reference RTS endpoint, printing every frame it applies."""

from __future__ import annotations

import argparse
import time
from typing import Any

from .. import interrupts
from .common import EXIT_OK, check_number, stdout_reader_gone


def _do_listen(args: argparse.Namespace) -> int:
    from ..errors import RtsError
    from ..outputs.udp import UdpReceiver

    host, port = _address(args.address)
    if args.count is not None and args.count < 1:
        raise RtsError(f"--count: must be >= 1, got {args.count}")
    if args.seconds is not None:
        check_number("--seconds", args.seconds, low=0.001, high=86400.0)
    try:
        receiver = UdpReceiver(host, port, keep_applied=True)
    except (OSError, OverflowError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise RtsError(f"{args.address}: cannot listen: {reason}") from None
    receiver.start()
    bound_host, bound_port = receiver.address
    print(f"listening on udp://{bound_host}:{bound_port}", flush=True)
    shown = 0
    datagrams = 0
    quiet_since = time.monotonic()
    try:
        while args.count is None or shown < args.count:
            # Taken as they come, so that they do not pile up over a long stream.
            receiver.arrival_s.clear()
            applied = receiver.applied
            while applied and (args.count is None or shown < args.count):
                frame, t_s, entries = applied.popleft()
                shown += 1
                active = int((entries["flags"] & 1).astype(bool).sum())
                print(f"frame {frame} t {t_s:.3f} s: {entries.size} entries, {active} active",
                      flush=True)
            if receiver.stats.datagrams != datagrams:
                datagrams = receiver.stats.datagrams
                quiet_since = time.monotonic()
            elif args.seconds is not None and time.monotonic() - quiet_since >= args.seconds:
                break
            if stdout_reader_gone():  # printing is all it does (`rts-listen ... | head`)
                break
            time.sleep(0.01)
    except KeyboardInterrupt:
        interrupts.handled()  # how it is stopped
    finally:
        stats = receiver.stop(drain_s=0.0)
    print(f"{shown} frames shown; {stats.frames_applied} applied, {stats.datagrams} datagrams, "
          f"{stats.corrupted} corrupted, {stats.malformed} malformed, {stats.lost_frames} frames "
          f"lost" + (f", {stats.stale_frames} frames came too late (after a newer one)"
                     if stats.stale_frames else ""), flush=True)
    return EXIT_OK


def _address(spec: str, option: str = "ADDRESS") -> tuple[str, int]:
    """``(host, port)`` of a ``udp://HOST:PORT`` the command listens on, given as ``option``."""
    from ..errors import RtsError

    usage = "expected udp://HOST:PORT with a port 0..65535 (0: any free port)"
    if not spec.startswith("udp://"):
        raise RtsError(f"{option} {spec!r}: {usage}")
    host, _, port = spec[len("udp://"):].rpartition(":")
    if not host or not (port.isascii() and port.isdigit()) or not 0 <= int(port) < 65536:
        raise RtsError(f"{option} {spec!r}: {usage}")
    return host.strip("[]"), int(port)


def add_parser(subparsers: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Add the ``rts-listen`` subcommand."""
    parser = subparsers.add_parser(
        "rts-listen", help="receive schedule datagrams like an RTS and print each frame",
        parents=parents,
        description="Run the reference UDP receiver (the protocol of docs/udp-protocol.md): "
                    "validate, reassemble and apply every frame, print one line per applied "
                    "frame. Ends after --count frames, --seconds of silence or Ctrl-C.",
    )
    parser.add_argument("address", metavar="ADDRESS", help="udp://HOST:PORT to listen on")
    parser.add_argument("--count", type=int, default=None, help="stop after this many frames")
    parser.add_argument("--seconds", type=float, default=None,
                        help="stop after this many seconds without a datagram")
    parser.set_defaults(handler=_do_listen)
