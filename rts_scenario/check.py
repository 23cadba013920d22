"""Compare the radar's detections with the scene's ground truth: errors, rates, verdict.

Per frame, detections are associated with the targets the RTS played (gated at 3x each
quantity's tolerance, then an optimal assignment on the normalized distance). A checkable
target (present, synthesizable, unambiguous for the radar, played) counts as detected in a
frame when a detection is assigned to it and every checked quantity lies within its tolerance.

Verdict (pass only if all hold): every target's detection rate reaches the scene's
``detection_rate``; false detections per frame stay within ``max_false_detections_per_frame``;
and no frame that had something to check is missing, incomplete or corrupted - such frames
count as missed and fail the run, so missing data can never pass.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from .canbus import DetectionReceiver
from .kinematics import Tracks
from .report import ErrorStats, Report, TargetResult
from .scenario.model import Expectations

FloatArray = NDArray[np.float64]

# Checked quantity: (track attribute, mapping quantity, tolerance key).
QUANTITIES = (
    ("range_m", "range_m", "range_m"),
    ("radial_velocity_mps", "radial_velocity_mps", "radial_velocity_mps"),
    ("az_deg", "azimuth_deg", "az_deg"),
    ("el_deg", "elevation_deg", "el_deg"),
    ("rcs_dbsm", "rcs_dbsm", "rcs_db"),
)
GATE = 3.0


def check(scene: str, tracks: Tracks, played: NDArray[np.bool_], receiver: DetectionReceiver,
          expectations: Expectations) -> Report:
    """Check what the receiver reassembled against the ground truth.

    Parameters
    ----------
    scene : str
        Scene name, for the report.
    tracks : Tracks
        Ground truth, (F, K).
    played : ndarray of bool, shape (F, K)
        Targets the RTS played (the schedule's emitted entries).
    receiver : DetectionReceiver
        The radar's frames as received from the bus (frame counter = scene frame index).
    expectations : Expectations
        Tolerances and required rates.
    """
    n_frames, n_targets = tracks.range_m.shape
    tol = expectations.tolerances
    available = receiver.mapping.quantities
    checked_q = [(attr, q, key) for attr, q, key in QUANTITIES if q in available]
    truth = tracks.checkable & played
    halves = receiver.halves_per_detection
    status = np.zeros(n_frames, dtype=np.int8)  # 0 ok, 1 missing, 2 incomplete
    det: dict[str, list[FloatArray]] = {q: [] for _, q, _ in checked_q}
    det_frame: list[int] = []
    for f in range(n_frames):  # reassembled frames come one by one from the receiver
        frame = receiver.frames.get(f & 0xFFFF)
        if frame is None:
            status[f] = 1
            continue
        if not frame.complete(halves):
            status[f] = 2
            continue
        values = receiver.detections(f & 0xFFFF)
        count = len(frame.parts)
        for _, q, _ in checked_q:
            det[q].append(values[q])
        det_frame.extend([f] * count)
    frame_of = np.asarray(det_frame, dtype=np.int64)
    d_values = {q: np.concatenate(v) if v else np.zeros(0) for q, v in det.items()}

    # Gate and cost for every (detection, target) pair of the same frame.
    cost = np.zeros((frame_of.size, n_targets))
    inside = np.ones((frame_of.size, n_targets), dtype=bool)
    diffs = {}
    for attr, q, key in checked_q:
        truth_q = getattr(tracks, attr)[frame_of]  # (D, K)
        diff = d_values[q][:, None] - truth_q
        if attr == "az_deg":
            diff = (diff + 180.0) % 360.0 - 180.0
        diffs[attr] = diff
        if attr != "rcs_dbsm":  # RCS fluctuates: it does not decide who is who
            norm = diff / tol[key]
            cost += norm * norm
            inside &= np.abs(norm) <= GATE
    candidates = inside & played[frame_of]
    match_target = _assign(frame_of, candidates, cost)

    matched = match_target >= 0
    errors = {attr: np.full((n_frames, n_targets), np.nan) for attr, _, _ in checked_q}
    for attr in errors:
        errors[attr][frame_of[matched], match_target[matched]] = diffs[attr][
            np.flatnonzero(matched), match_target[matched]]
    within = np.ones((n_frames, n_targets), dtype=bool)
    assigned = np.zeros((n_frames, n_targets), dtype=bool)
    assigned[frame_of[matched], match_target[matched]] = True
    for attr, _, key in checked_q:
        within &= ~(np.abs(errors[attr]) > tol[key])
    detected = assigned & within & truth

    unchecked = (status > 0)[:, None] & truth
    false_det = int((~matched).sum())
    checked_frames = int((status == 0).sum())
    targets = []
    for k, name in enumerate(tracks.names):  # one summary row per target
        n_check = int(truth[:, k].sum())
        n_det = int(detected[:, k].sum())
        rate = n_det / n_check if n_check else float("nan")
        stats = {attr: ErrorStats.of(errors[attr][:, k][truth[:, k]]) for attr, _, _ in
                 checked_q}
        for attr, _, _ in QUANTITIES:
            stats.setdefault(attr, ErrorStats.of(np.zeros(0)))
        targets.append(TargetResult(name=name, checkable_frames=n_check, detected_frames=n_det,
                                    detection_rate=rate, errors=stats,
                                    passed=n_check == 0
                                    or rate >= expectations.detection_rate - 1e-12))
    reasons = [f"{t.name}: detection rate {t.detection_rate:.1%} < "
               f"{expectations.detection_rate:.1%}" for t in targets if not t.passed]
    per_frame = false_det / max(checked_frames, 1)
    if per_frame > expectations.max_false_detections_per_frame:
        reasons.append(f"{per_frame:.3f} false detections per frame > "
                       f"{expectations.max_false_detections_per_frame:g}")
    if unchecked.any():
        reasons.append(f"{int((status == 1).sum())} frames missing and "
                       f"{int((status == 2).sum())} incomplete: "
                       f"{int(unchecked.sum())} target-frames could not be checked")
    bus = receiver.stats
    if bus.messages == 0:
        reasons.append("the bus was silent: no message received")
    lost = {"checksum errors": bus.checksum_errors, "undecodable messages": bus.decode_errors,
            "detections without a frame header": bus.orphans}
    reasons += [f"{v} {k}" for k, v in lost.items() if v]
    if not truth.any():
        reasons.append("nothing to check: no target was checkable in any frame")
    all_stats = {attr: ErrorStats.of(errors[attr][truth]) for attr, _, _ in checked_q}
    n_truth = int(truth.sum())
    return Report(
        scene=scene, passed=not reasons, reasons=reasons,
        frames={"total": n_frames, "checked": checked_frames,
                "missing": int((status == 1).sum()), "incomplete": int((status == 2).sum()),
                "late": bus.reordered},
        targets=targets, errors=all_stats,
        detection_rate=float(detected.sum() / n_truth) if n_truth else float("nan"),
        false_detections=false_det, false_detections_per_frame=per_frame,
        bus=asdict(bus),
        per_frame={"t_s": tracks.t_s, "detected": detected, "checkable": truth,
                   "frame_status": status, **{f"error_{a}": e for a, e in errors.items()}},
    )


def _assign(frame_of: NDArray[np.int64], candidates: NDArray[np.bool_],
            cost: FloatArray) -> NDArray[np.int64]:
    """Target assigned to each detection (-1: none), optimal per frame.

    Where every detection has at most one candidate and every target at most one detection
    (the usual case), that is the answer; frames with a choice go to the Hungarian method.
    """
    out = np.full(frame_of.size, -1, dtype=np.int64)
    if frame_of.size == 0:
        return out
    per_det = candidates.sum(axis=1)
    targets_hit = np.zeros((int(frame_of.max()) + 1, candidates.shape[1]), dtype=np.int64)
    np.add.at(targets_hit, frame_of, candidates.astype(np.int64))
    ambiguous_frames = np.asarray((targets_hit > 1).any(axis=1), dtype=bool)
    simple = (per_det == 1) & ~ambiguous_frames[frame_of]
    out[simple] = np.argmax(candidates[simple], axis=1)
    hard = np.flatnonzero(ambiguous_frames)
    for f in hard:  # only frames where two detections compete for a target
        rows = np.flatnonzero(frame_of == f)
        c = np.where(candidates[rows], cost[rows], 1e9)
        r, k = linear_sum_assignment(c)
        ok = candidates[rows[r], k]
        out[rows[r[ok]]] = k[ok]
    return out
