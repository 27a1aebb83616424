"""Small datasets the tests write themselves: TrajNet++ ndjson scenes and raw BIWI EWAP obsmat files."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

STEP = 10  # frames per time step, as in BIWI hotel


def scene(sid: int, primary: int, start: int, end: int, tag: object = 0) -> dict:
    return {"scene": {"id": sid, "p": primary, "s": start, "e": end, "fps": 2.5, "tag": tag}}


def track(frame: int, ped: int, x: float, y: float) -> dict:
    return {"track": {"f": frame, "p": ped, "x": x, "y": y}}


def write_lines(path: Path, records: list[dict | str]) -> Path:
    """One line per record; strings are written verbatim (for malformed lines)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        "".join((r if isinstance(r, str) else json.dumps(r)) + "\n" for r in records), encoding="utf-8"
    )
    return path


def walk_scene_records(sid: int = 0, start: int = 0) -> list[dict]:
    """A 21-step scene with hand-checkable numbers.

    Pedestrian 1 (primary) walks +x at 0.5 m per step from (0, 0); pedestrian 2 walks beside it at y = 1;
    pedestrian 3 stands at (5, 5) during the first 3 steps only.
    """
    records: list[dict] = [scene(sid, 1, start, start + 20 * STEP)]
    for k in range(21):
        f = start + k * STEP
        records.append(track(f, 1, 0.5 * k, 0.0))
        records.append(track(f, 2, 0.5 * k, 1.0))
        if k < 3:
            records.append(track(f, 3, 5.0, 5.0))
    return records


def write_walk_file(path: Path) -> Path:
    """Two scenes: the walk above, and a second with pedestrian 2 as primary over the same frames."""
    records = walk_scene_records()
    records.insert(1, scene(1, 2, 0, 20 * STEP))
    return write_lines(path, records)


def write_crowds(path: Path) -> Path:
    """Five scenes of 3, 1, 2, 3 and 4 agents, for batches of scenes of unlike sizes: the walk above (its
    third pedestrian there for 3 steps only is still an agent of the window), then scenes of a primary and
    0 to 3 walkers beside it."""
    records: list[dict] = walk_scene_records(sid=0, start=0)
    for n in range(1, 5):
        start = 1000 * n
        records.append(scene(n, 10 * n, start, start + 20 * STEP))
        for k in range(21):
            records += [track(start + k * STEP, 10 * n + a, 0.5 * k, float(a)) for a in range(n)]
    return write_lines(path, records)


def ewap_rows(n_frames: int, frame_step: int, pairs_every: int = 12, steps: int = 23) -> np.ndarray:
    """Raw obsmat rows (8 columns, 1-based frames) of pairs of pedestrians crossing a square.

    Pair k enters at time index ``pairs_every * k`` and walks ``steps`` steps at 0.48 m per step, its two
    members 0.8 m apart, so every pair is "close" and yields TrajNet++ scenes.
    """
    rows = []
    pair = 0
    while pairs_every * pair + steps <= n_frames:
        t0 = pairs_every * pair
        heading = np.pi / 7 * pair
        direction = np.array([np.cos(heading), np.sin(heading)])
        normal = np.array([-direction[1], direction[0]])
        for member in (0, 1):
            ped = 2 * pair + member + 1
            for k in range(steps):
                pos = 0.48 * k * direction + 0.8 * member * normal + np.array([2.0, 3.0])
                vel = 1.2 * direction
                rows.append([1 + (t0 + k) * frame_step, ped, pos[0], 0.0, pos[1], vel[0], 0.0, vel[1]])
        pair += 1
    rows.sort(key=lambda r: (r[0], r[1]))
    return np.asarray(rows)


def write_obsmat(path: Path, rows: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["".join(f"{v:16.7e}" for v in row) for row in rows]
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())  # EWAP files have CRLF endings
    return path


def write_tiny_ewap(root: Path, n_frames: int = 300) -> Path:
    """``root/raw_ewap/seq_{eth,hotel}/obsmat.txt`` with frame steps 6 and 10; returns ``root/raw_ewap``."""
    raw = root / "raw_ewap"
    write_obsmat(raw / "seq_eth" / "obsmat.txt", ewap_rows(n_frames, 6))
    write_obsmat(raw / "seq_hotel" / "obsmat.txt", ewap_rows(n_frames, 10, pairs_every=9))
    return raw


def shared_data_dir() -> Path | None:
    """The team's shared data: ``$CROWDMPC_DATA`` or ``../shared/data`` beside the repository, if it holds
    the raw EWAP files and the official TrajNet++ hotel file."""
    import os

    candidates = [os.environ.get("CROWDMPC_DATA"), Path(__file__).resolve().parents[3] / "shared" / "data"]
    for candidate in candidates:
        if not candidate:
            continue
        root = Path(candidate)
        if (root / "raw_ewap" / "seq_hotel" / "obsmat.txt").is_file() and (
            root / "trajnetpp_vita" / "train" / "real_data" / "biwi_hotel.ndjson"
        ).is_file():
            return root
    return None


def vouch_for(prepared: Path, name: str) -> None:
    """Record the file ``name`` of the prepared folder ``prepared`` as it is now in its manifest (which
    refuses a file that is not the one it lists), so that a test's edit reaches the parser."""
    manifest = json.loads((prepared / "manifest.json").read_text())
    data = (prepared / name).read_bytes()
    manifest["files"][name].update(sha256=hashlib.sha256(data).hexdigest(), bytes=len(data))
    (prepared / "manifest.json").write_text(json.dumps(manifest))
