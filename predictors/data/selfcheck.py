"""The self-check of the conversion: our scenes of a whole raw sequence against a TrajNet++ conversion of it,
since a reimplemented converter is only trusted as far as it reproduces the converter's own files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from predictors.data.trajnet_io import read_scenes
from predictors.data.trajnet_scenes import STATIC_THRESHOLD, build_scenes, write_ndjson


@dataclass(frozen=True)
class Reference:
    """A TrajNet++ conversion of one whole raw sequence to check ours against."""

    path: Path
    label: str  # how the report names it, e.g. "official TrajNet++"
    compare_tags: bool = True  # costs one Kalman fit per moving scene


@dataclass(frozen=True)
class SelfCheck:
    """Our full-sequence conversion of a sequence against a reference TrajNet++ file of it."""

    reference: str
    label: str
    reference_scenes: int
    reproduced: int  # same primary, start, end, agents and every coordinate within tolerance
    ours: int  # scenes in our full-sequence conversion, before acceptance
    ours_static_not_in_reference: int
    ours_moving_not_in_reference: int
    tags_compared: int
    tags_agree: int
    mismatches: tuple[str, ...] = field(default_factory=tuple)  # first few reasons, for the report


def compare_with_reference(
    tracks: np.ndarray,
    reference: Reference,
    *,
    frame_step: int,
    workdir: Path,
    tolerance: float = 1e-6,
    progress: bool | None = False,
) -> SelfCheck:
    """Convert the whole sequence (no split, nothing dropped by acceptance) and look up each reference scene.

    The fair comparison for TrajNet++'s files: they convert a sequence whole (hotel is train-only, ETH
    test-only in TrajNet++) and then drop static scenes at random, so every reference scene should be among
    ours and the extra ones should all be static.
    """
    with_tags = reference.compare_tags
    ours = build_scenes(
        tracks, frame_step=frame_step, categorize_scenes=with_tags, acceptance=None, progress=progress
    )
    ours_path = workdir / f"whole_{Path(reference.path).stem}.ndjson"
    write_ndjson(ours_path, ours, tracks)
    ours_by_key = {(s.primary, s.start, s.end): s for s in read_scenes(ours_path)}
    reference_scenes = read_scenes(reference.path)
    matched: set[tuple[int, int, int]] = set()
    mismatches: list[str] = []
    tags_compared = tags_agree = 0
    for ref in reference_scenes:
        key = (ref.primary, ref.start, ref.end)
        mine = ours_by_key.get(key)
        if mine is None:
            mismatches.append(f"scene {ref.id} {key}: not among ours")
            continue
        problem = _scene_difference(ref, mine, tolerance)
        if problem:
            mismatches.append(f"scene {ref.id} {key}: {problem}")
            continue
        matched.add(key)
        if with_tags and isinstance(ref.tag, list):
            tags_compared += 1
            tags_agree += ref.tag == mine.tag
    extra = [s for k, s in ours_by_key.items() if k not in matched]
    static = sum(_is_static(s) for s in extra)
    return SelfCheck(
        reference=str(reference.path),
        label=reference.label,
        reference_scenes=len(reference_scenes),
        reproduced=len(matched),
        ours=len(ours_by_key),
        ours_static_not_in_reference=static,
        ours_moving_not_in_reference=len(extra) - static,
        tags_compared=tags_compared,
        tags_agree=tags_agree,
        mismatches=tuple(mismatches[:10]),
    )


def _is_static(scene) -> bool:
    first, last = scene.xy[0, 0], scene.xy[-1, 0]
    return bool(np.hypot(*(first - last)) < STATIC_THRESHOLD)


def _scene_difference(ref, mine, tolerance: float) -> str | None:
    if not np.array_equal(ref.frames, mine.frames):
        return "different primary frames"
    if set(ref.agents.tolist()) != set(mine.agents.tolist()):
        return f"agents differ: {sorted(set(ref.agents.tolist()) ^ set(mine.agents.tolist()))}"
    order = [int(np.flatnonzero(mine.agents == a)[0]) for a in ref.agents]
    a, b = ref.xy, mine.xy[:, order]
    if not np.array_equal(np.isnan(a), np.isnan(b)):
        return "different missing entries"
    gap = np.nanmax(np.abs(a - b)) if np.isfinite(a).any() else 0.0
    return None if gap <= tolerance else f"coordinates differ by up to {gap:.3g} m"


def default_references(raw_dir: str | Path) -> dict[str, Reference]:
    """Reference conversions found beside a raw EWAP directory laid out like the team's shared data:
    the official TrajNet++ hotel file, and pedro-mgb's (unofficial) whole-ETH conversion."""
    return {name: ref for name, ref in expected_references(raw_dir).items() if ref.path.is_file()}


def expected_references(raw_dir: str | Path) -> dict[str, Reference]:
    """Where ``default_references`` looks for each reference conversion, found there or not."""
    root = Path(raw_dir).resolve().parent
    return {
        "biwi_hotel": Reference(
            root / "trajnetpp_vita" / "train" / "real_data" / "biwi_hotel.ndjson", "official TrajNet++", True
        ),
        # tags skipped: one Kalman fit per scene of the whole of ETH would add about a minute
        "biwi_eth": Reference(
            root / "trajnetpp_pedro-mgb" / "test_private" / "real_data" / "biwi_eth.ndjson",
            "unofficial (pedro-mgb, TrajNet++ converter)",
            False,
        ),
    }


def describe_check(name: str, check: SelfCheck) -> list[str]:
    lines = [
        f"self-check {name}: reproduced {check.reproduced} / {check.reference_scenes} scenes of the "
        f"{check.label} file {check.reference} exactly (same primary, start, end, agents, every coordinate "
        "within 1e-6)",
        f"  our whole-sequence conversion has {check.ours} scenes before acceptance; of those not in the "
        f"reference, {check.ours_static_not_in_reference} are static (type I, which TrajNet++ keeps at "
        f"random with probability 0.1) and {check.ours_moving_not_in_reference} are moving",
    ]
    if check.tags_compared:
        lines.append(
            f"  categorisation tags agree on {check.tags_agree} / {check.tags_compared} reproduced scenes "
            "(type II rests on a sampled Kalman prediction, so borderline scenes can flip)"
        )
    lines.extend(f"  mismatch: {m}" for m in check.mismatches)
    return lines
