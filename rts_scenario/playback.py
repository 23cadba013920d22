"""How the schedule was played: when each frame went out, and what the RTS says it applied.

A sender paced in real time puts each frame out at its scene time or a little later (the
operating system's scheduling); the RTS cannot apply a frame before it arrives. The checker
judges every radar cycle by when frames really went out (`rts_scenario.pipeline.CycleTruth`),
so a late frame does not make the radar look wrong. Lateness is always reported (median,
worst). A frame that went out later than its whole slot (the scene's frame period, never
shorter than the rig's update interval) left the frame before held for another frame: the scene
was not played as specified, and such frames fail the run unless the scene declares
``frames_sent_late`` expected. A shorter delay shifts the scene's timeline by less than a frame,
which the checker already accounts for; failing on it would fail runs on an ordinary loaded
machine for what the verdict already judges correctly.

A UDP sender cannot see a datagram lost on the way. An RTS that reports its counters
(``udp-protocol.md``: status datagrams; the reference receiver and ``rts-scenario emulate``
do) lets the run say how many frames it lost or could not apply; those fail the run unless
the scene declares ``frames_lost`` expected. Without such reports a lost frame shows only as
what the radar measured: the frame before held longer (misses, or errors beyond tolerance).
"""

from __future__ import annotations

import base64
import binascii
import errno
import os
import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .report import FailReason, RunningStats
from .schedule.model import SAME_TIME_S

# RTS counters that mean frames were not played as sent.
LOST_COUNTERS = ("lost_frames", "unsynced_frames", "corrupted", "malformed")


class Playback:
    """Running account of a run's playback (see the module docstring).

    Parameters
    ----------
    late_after_s : float
        A frame that went out later than this after its time is late (the scene's frame
        period).
    ambiguity_window_s : float
        The window after a frame change in which a cycle may show the frame before
        (`rts_scenario.pipeline.ambiguity_window_s`), reported with the rest.
    """

    def __init__(self, late_after_s: float, ambiguity_window_s: float) -> None:
        self.late_after_s = float(late_after_s)
        self.ambiguity_window_s = float(ambiguity_window_s)
        self._lateness = RunningStats(1)
        self.frames = 0
        self.late_frames = 0
        self.rts: dict[str, int] | None = None
        # What the network said of datagrams nothing received (`Output.rts_unreachable`).
        self.rts_unreachable: dict[str, Any] | None = None
        # What the RTS said of its rig (`rts_rig_record`), None where it said nothing.
        self.rts_rig: dict[str, Any] | None = None
        # Every frame's lateness, compressed as it comes (a few bytes per frame where the
        # sender's timing varies, nearly nothing where it does not): a log's re-check judges
        # the radar's cycles by the same send times as the run did.
        self._packer = zlib.compressobj(9)
        self._packed: list[bytes] = []

    def add(self, t_s: ArrayLike, sent_s: ArrayLike) -> None:
        """Take a batch's frame times and the scene times they went out at."""
        late = np.asarray(sent_s, dtype=np.float64) - np.asarray(t_s, dtype=np.float64)
        self.frames += late.size
        self.late_frames += int((late > self.late_after_s).sum())
        self._lateness.add(late.reshape(-1, 1))
        # Rounded up: a frame that went out after its time (beyond SAME_TIME_S) stays after
        # it, so a cycle measured at the frame's time is judged against the frame before, as
        # the run judged it (a paced UDP sender is some tens of nanoseconds late every frame).
        late_us = np.clip(np.ceil((late.reshape(-1) - SAME_TIME_S) * 1e6), 0,
                          np.iinfo(np.int32).max)
        self._packed.append(self._packer.compress(late_us.astype("<i4").tobytes()))

    def send_lateness(self) -> dict[str, Any]:
        """Every frame's lateness (`SEND_LATENESS_ENCODING`), for a log's sidecar; call once."""
        data = b"".join([*self._packed, self._packer.flush()])
        return {"frames": self.frames, "encoding": SEND_LATENESS_ENCODING,
                "data": base64.b64encode(data).decode("ascii")}

    def to_dict(self) -> dict[str, Any]:
        """Plain data for the report's ``playback`` (docs/report.md)."""
        stats = self._lateness.result()
        return {"frames_sent": self.frames, "late_frames": self.late_frames,
                "lateness_s": {"p50": stats.p50, "p95": stats.p95, "max": stats.max},
                "late_after_s": self.late_after_s,
                "ambiguity_window_s": self.ambiguity_window_s, "rts": self.rts,
                "rts_rig": self.rts_rig, "rts_unreachable": self.rts_unreachable}

    def reasons(self, expected: frozenset[str] | set[str]) -> list[str]:
        """Why the playback fails the run (nothing when it does not)."""
        return playback_reasons(self.to_dict(), expected)

    def not_hit(self, expected: frozenset[str] | set[str]) -> list[str]:
        """Return the playback limits the scene expects that the run did not hit."""
        return playback_not_hit(self.to_dict(), expected)


def playback_reasons(playback: Mapping[str, Any], expected: frozenset[str] | set[str]
                     ) -> list[str]:
    """Why a playback (`Playback.to_dict`, e.g. from a log's sidecar) fails the run."""
    out: list[str] = []
    late, frames = int(playback["late_frames"]), int(playback["frames_sent"])
    rts = playback.get("rts")
    if late and "frames_sent_late" not in expected:
        worst = playback["lateness_s"]["max"]
        out.append(FailReason(
            f"frames_sent_late: {late} of {frames} frames went out more than a frame period "
            f"({playback['late_after_s'] * 1e3:.3g} ms) after their time: the frame before was "
            f"held instead (worst {worst * 1e3:.3g} ms)", "frames_sent_late"))
    out += stream_reasons(rts, playback.get("rts_rig"))
    if "frames_lost" not in expected:
        out += delivery_reasons(rts, playback.get("rts_unreachable"))
    return out


def playback_limits(playback: Mapping[str, Any]) -> dict[str, str]:
    """Return the scene-wide limits the playback hit and why, expected by the scene or not.

    ``frames_sent_late`` (frames went out late), ``frames_lost`` (the RTS lost or did not
    apply frames): the report's ``scene_limits`` list them as they list every scene-wide limit
    hit. Datagrams that came back undelivered are no RTS's limit (``rts_unreachable``, a
    reason of its own).
    """
    out: dict[str, str] = {}
    for reason in playback_reasons(playback, frozenset()):
        code = reason.codes[0] if isinstance(reason, FailReason) and reason.codes else ""
        if code in ("frames_sent_late", "frames_lost"):
            out[code] = str(reason).removeprefix(f"{code}: ")
    return out


def stream_reasons(rts: Mapping[str, int] | None, rig: Mapping[str, Any] | None,
                   who: str = "run") -> list[str]:
    """Why what the RTS played is not the stream's, whatever the scene expects.

    ``rig``: what it said of its rig (`rts_rig_record`): another rig plays other directions;
    ``rts``: its counters, where they count datagrams another sender sent (its stream took the
    RTS over). ``who``: the sender, as the reasons name it.
    """
    out: list[str] = []
    if rig is not None and not rig["matches_run"]:
        played = rts is None or int(rts.get("frames_applied", 0)) > 0
        whose = f"the {who}'s"
        out.append(FailReason(
            f"rts_rig: the RTS plays a rig of {rig_difference(rig, whose)}: "
            + ("its echoes came from other directions than the schedule put them in"
               if played else f"it applied none of the {who}'s frames")
            + f"; {who} on the rig the RTS has (emulate: --rig the {who}'s)", "rts_rig"))
    if rts and rts.get("foreign_datagrams"):
        out.append(FailReason(
            f"rts_stream: the RTS's counters count {rts['foreign_datagrams']} datagrams more "
            f"than this {who} sent ({int(rts['datagrams'])} in all): another sender's stream "
            f"took the RTS over (a second run against it?), so what it played and counted is "
            f"not this {who}'s", "rts_stream"))
    return out


def rig_difference(rig: Mapping[str, Any], whose: str) -> str:
    """How the RTS's rig (`rts_rig_record`) differs from ``whose`` (e.g. "the run's")."""
    if rig.get("run_front_ends", rig["front_ends"]) != rig["front_ends"]:
        return f"{rig['front_ends']} FEs, not the {rig['run_front_ends']} of {whose} ({rig['run']})"
    return (f"{rig['front_ends']} FEs whose geometry (sha256 {rig['geometry_sha256'][:12]}) is "
            f"not {whose} ({rig['run']}, {rig['run_geometry_sha256'][:12]})")


def delivery_reasons(rts: Mapping[str, int] | None, gone: Mapping[str, Any] | None,
                     within: str = "of the scene") -> list[str]:
    """Why the RTS did not play every frame: datagrams back undelivered, frames it lost.

    ``rts``: its counters (`Output.rts_status`); ``gone``: what the network said of datagrams
    nothing received (`Output.rts_unreachable`). A scene that declares ``frames_lost`` is not
    failed for them (`playback_reasons`; `rts-scenario schedule` tells them).
    """
    out: list[str] = []
    if gone:
        out.append(FailReason(unreachable_reason(gone, within), "rts_unreachable"))
    lost = lost_frames(rts)
    if lost:
        unaccounted = int((rts or {}).get("unaccounted_frames", 0))
        out.append(FailReason(
            f"frames_lost: the RTS reports {lost} schedule frames it did not apply ("
            + ", ".join(f"{k.replace('_', ' ')} {rts[k]}"
                        for k in LOST_COUNTERS if rts and rts.get(k)) + ")"
            + (f"; {unaccounted} of them by the sender's count: frames its last reply, "
               f"waited for at the stream's end, did not count as applied (lost on the way, "
               f"still pending there, or its reply lost or late)" if unaccounted else ""),
            "frames_lost"))
    return out


def playback_not_hit(playback: Mapping[str, Any], expected: frozenset[str] | set[str]
                     ) -> list[str]:
    """Return the playback's scene-wide limits ``expected`` declares that the run did not hit.

    ``frames_sent_late``: no frame went out late. ``frames_lost``: the RTS reported its
    counters and lost or left unapplied no frame; an RTS that reports none cannot tell, and
    the limit is not said (sorted names, as `rts_scenario.report.Report.expected_not_hit`).
    """
    out = []
    if "frames_lost" in expected and playback.get("rts") is not None \
            and not lost_frames(playback["rts"]) and not playback.get("rts_unreachable"):
        out.append("frames_lost")
    if "frames_sent_late" in expected and not int(playback["late_frames"]):
        out.append("frames_sent_late")
    return out


def unreachable_reason(gone: Mapping[str, Any], within: str = "of the scene") -> str:
    """Why datagrams the network sent back (`Output.rts_unreachable`) fail a run."""
    why = ("nothing listened on that port: is the RTS running, and on this address and port?"
           if gone["error"] == os.strerror(errno.ECONNREFUSED)
           else "check the RTS's address and the network to it")
    span = (f"at {gone['first_s']:.2f} s" if gone["first_s"] == gone["last_s"]
            else f"from {gone['first_s']:.2f} s to {gone['last_s']:.2f} s")
    return (f"rts_unreachable: {gone['datagrams']} datagrams to udp://{gone['address']} came "
            f"back undelivered ({gone['error']}) {span} {within}: the RTS never played their "
            f"frames; {why}")


def rts_rig_record(said: tuple[int, bytes] | None, rig: Any) -> dict[str, Any] | None:
    """Return the report's ``playback.rts_rig``: what the RTS said of its rig, against ``rig``.

    ``said``: its FE count and geometry digest (`rts_scenario.rig.Rig.geometry_digest`), None
    where the RTS said nothing (then None: it cannot be told).
    """
    if said is None:
        return None
    front_ends, digest = said
    own = rig.geometry_digest()
    return {"front_ends": front_ends, "geometry_sha256": digest.hex(), "run": rig.name,
            "run_front_ends": rig.n_front_ends, "run_geometry_sha256": own.hex(),
            "matches_run": front_ends == rig.n_front_ends and digest == own}


# How `Playback.send_lateness` packs when each frame went out after its time.
SEND_LATENESS_ENCODING = "int32 little-endian microseconds per frame, zlib, base64"


def unpack_send_lateness(record: Mapping[str, Any], n_frames: int) -> NDArray[np.float64]:
    """Each frame's lateness (s) from a `Playback.send_lateness` record of ``n_frames`` frames.

    Raises
    ------
    ValueError
        The record is not one `Playback.send_lateness` writes, or not of ``n_frames`` frames.
    """
    if record.get("encoding") != SEND_LATENESS_ENCODING:
        raise ValueError(f"encoding: must be {SEND_LATENESS_ENCODING!r}, got "
                         f"{record.get('encoding')!r}")
    try:
        raw = zlib.decompress(base64.b64decode(str(record.get("data", "")), validate=True))
    except (binascii.Error, zlib.error) as exc:
        raise ValueError(f"data: not zlib-compressed base64 ({exc})") from None
    if len(raw) != 4 * n_frames or record.get("frames") != n_frames:
        raise ValueError(f"holds {len(raw) // 4} frames (says {record.get('frames')}), the "
                         f"scene has {n_frames}")
    late = np.frombuffer(raw, dtype="<i4").astype(np.float64) * 1e-6
    if late.size and late.min() < 0.0:
        k = int(np.argmin(late))
        raise ValueError(f"frame {k} went out {-late[k]:g} s before its time: a run writes "
                         f"every frame's lateness as 0 or more")
    return late


def lost_frames(rts: Mapping[str, int] | None) -> int:
    """Return how many frames an RTS's counters say were lost or not applied (0 for None)."""
    if not rts:
        return 0
    return int(rts.get("lost_frames", 0)) + int(rts.get("unsynced_frames", 0))


__all__ = ["LOST_COUNTERS", "SEND_LATENESS_ENCODING", "Playback", "delivery_reasons",
           "rig_difference", "stream_reasons",
           "lost_frames",
           "playback_limits", "playback_not_hit", "playback_reasons", "rts_rig_record",
           "unpack_send_lateness",
           "unreachable_reason"]
