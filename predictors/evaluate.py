"""Evaluate any registered predictor on TrajNet++ scenes (``crowdmpc evaluate``).

Every scene gives the predictor its first ``obs_len`` steps of every agent observed in them (world
coordinates, absent entries 0 with ``mask`` False, the primary first) and asks for ``pred_len`` steps of
all of them (``humans`` = every agent); there are no robots (``robots_future=None``). A trained model whose
config reads fewer steps (``obs_len`` 3 of a zoo entry edited by hand) is given the last of them only, and
the agents seen there, as TrajNet++'s baselines hand a model ``xy[start_length:obs_length]`` of the scene's
9 observed steps (``handed_steps``); the scores keep the scene's own observation, so Col-II still counts
every neighbour seen in it and Col-I only the scenes whose every such neighbour the model predicted. A
predictor that also has ``sample(history, mask, robots_future, humans, horizon, k, rng) -> (k, H, N_h, 2)``
is scored top-k too.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from predictors.base import DT, OBS_LEN, PRED_LEN, ObservingPredictor, Predictor, check_steps
from predictors.data.trajnet_io import last_steps, scenes_of
from predictors.data.validate import NdjsonContent, parse_ndjson
from predictors.errors import PredictorError
from predictors.metrics import SceneScore, score_scene, summarize
from predictors.progress import progress_bar
from predictors.text_table import aligned_lines


@dataclass(frozen=True)
class EvalConfig:
    obs_len: int = OBS_LEN  # observed steps given to the predictor (TrajNet++: 9)
    pred_len: int = PRED_LEN  # predicted steps scored (TrajNet++: 12)
    top_k: int | None = None  # samples for top-k ADE/FDE (predictors with ``sample`` only)
    seed: int = 0  # seeds the generator passed to ``sample``

    def __post_init__(self):
        check_steps(self.obs_len, self.pred_len)
        if self.top_k is not None and self.top_k < 1:
            raise PredictorError(f"--top-k must be >= 1, got {self.top_k}")


def check_dataset_predictor(predictor: Predictor) -> None:
    """PredictorError naming ``predictor`` when it predicts from the simulator's state (an
    ``ObservingPredictor``, the ORCA oracle): a dataset scene has no goals or velocities to hand it, and its
    own refusal ("call observe(obs) first") speaks of an API a command-line user never calls."""
    if isinstance(predictor, ObservingPredictor):
        raise PredictorError(
            f"predictor {predictor.name!r} predicts from the simulator's state (goals, velocities), which "
            "dataset scenes do not have: evaluate a trained predictor or constant_velocity"
        )


def predict_scene(predictor: Predictor, xy: np.ndarray, config: EvalConfig, rng: np.random.Generator | None):
    """``(prediction, agents, samples)`` for one scene ``(obs_len + pred_len, N, 2)`` (NaN = absent).

    ``agents`` are the scene's agents observed at least once (the primary, agent 0, first); the predictor
    sees only those, all as humans, and ``prediction`` is ``(pred_len, len(agents), 2)`` in that order.
    """
    check_dataset_predictor(predictor)
    history, mask, agents = observed_history(xy, config.obs_len, handed_steps(predictor, config.obs_len))
    humans = np.arange(len(agents))
    prediction = np.asarray(predictor.rollout(history, mask, None, humans, horizon=config.pred_len))
    expected = (config.pred_len, len(agents), 2)
    if prediction.shape != expected:
        raise PredictorError(
            f"predictor {predictor.name!r} returned shape {prediction.shape}, expected {expected}"
        )
    check_finite(predictor, prediction, "prediction")
    samples = None
    if config.top_k is not None and hasattr(predictor, "sample"):
        samples = np.asarray(
            predictor.sample(history, mask, None, humans, config.pred_len, config.top_k, rng)
        )
        check_finite(predictor, samples, "samples")
    return prediction, agents, samples


def check_finite(predictor: Predictor, positions: np.ndarray, what: str) -> None:
    """PredictorError naming the first non-finite position a predictor returned: the scores would otherwise
    fail inside trajnetplusplustools with a bare AssertionError (a NaN primary), or count a NaN neighbour as
    absent where TrajNet++'s evaluator reads a present one that collides with nothing."""
    bad = np.argwhere(~np.isfinite(positions).all(axis=-1))
    if len(bad):
        *sample, step, agent = bad[0].tolist()
        where = f"sample {sample[0]}, " if sample else ""
        value = positions[tuple(bad[0])].tolist()
        raise PredictorError(
            f"predictor {predictor.name!r} returned a non-finite position {value} "
            f"in its {what} ({where}predicted step {step + 1}, agent {agent}); "
            "a predictor must return finite positions"
        )


def handed_steps(predictor: Predictor, obs_len: int) -> int:
    """How many of a scene's ``obs_len`` observed steps ``predictor`` is given, the last ones.

    A ``LearnedPredictor`` reads the last ``predictor.obs_len`` rows of a history and refuses an agent
    unseen in them: a zoo entry whose config reads 3 steps stopped at the first scene with a neighbour that
    left before them. It is given those rows alone, as the closed loop gives it (``predictor_history``) and as
    TrajNet++'s baselines give a model ``xy[start_length:obs_length]`` of the 9 observed steps. Any other
    predictor keeps every observed step: constant velocity (obs_len 2) reads them all, extrapolating a
    neighbour last seen earlier, and its scores stay what they were.
    """
    learned = sys.modules.get("predictors.learned")  # not imported: no LearnedPredictor exists (nor torch)
    if learned is not None and isinstance(predictor, learned.LearnedPredictor):
        return min(predictor.obs_len, obs_len)  # more than obs_len: refused by evaluate_scenes first
    return obs_len


def observed_history(
    xy: np.ndarray, obs_len: int, steps: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(history, mask, agents)`` of a scene ``(T, N, 2)`` (NaN = absent): the last ``steps`` (default: all)
    of its first ``obs_len`` steps, of the agents observed in them (``agents``, the primary first), absent
    entries 0 with ``mask`` False."""
    steps = obs_len if steps is None else steps
    observed = xy[obs_len - steps : obs_len]
    seen = ~np.isnan(observed).any(axis=-1)
    agents = np.flatnonzero(seen.any(axis=0))  # an agent that only appears later cannot be predicted
    mask = seen[:, agents]
    return np.where(mask[..., None], observed[:, agents], 0.0), mask, agents


@dataclass(frozen=True)
class EvalScene:
    """One scene cut to the evaluation window."""

    xy: np.ndarray  # (obs_len + pred_len, N, 2) metres, NaN where absent; agent 0 is the primary
    frames: np.ndarray  # (obs_len + pred_len,) frame ids


def load_eval_scenes(path: str | Path, config: EvalConfig = EvalConfig()) -> list[EvalScene]:
    """The scenes of one ndjson file, each cut to its last ``obs_len + pred_len`` steps."""
    return eval_scenes_of(parse_ndjson(path), config)


def eval_scenes_of(content: NdjsonContent, config: EvalConfig = EvalConfig()) -> list[EvalScene]:
    """``load_eval_scenes`` of a file ``parse_ndjson`` has already read: ``crowdmpc train`` builds the data
    module's arrays from the same parse."""
    path = content.summary.path
    length = config.obs_len + config.pred_len
    needs = (
        f"the evaluation needs {length} ({config.obs_len} observed + {config.pred_len} predicted); is this a "
        "test/ file without ground truth?"
    )
    scenes = []
    for scene in scenes_of(content, require_fps=1 / DT):
        cut = last_steps(scene, length, path, needs)
        scenes.append(EvalScene(cut.xy, cut.frames))
    return scenes


def score_scenes(
    predictor: Predictor, scenes: list[EvalScene], config: EvalConfig = EvalConfig(), progress=None
) -> list[SceneScore]:
    """Scores of ``scenes``; ``progress`` is a tqdm bar to advance (or None)."""
    rng = np.random.default_rng(config.seed)
    scores = []
    for scene in scenes:
        prediction, agents, samples = predict_scene(predictor, scene.xy, config, rng)
        scores.append(
            score_scene(prediction, agents.tolist(), scene.xy, scene.frames, config.obs_len, samples)
        )
        if progress is not None:
            progress.update(1)
    return scores


def evaluate(
    predictor: Predictor,
    files: list[Path],
    config: EvalConfig = EvalConfig(),
    *,
    progress: bool | None = None,
    root: Path | None = None,
) -> dict:
    """Per-file and overall (scenes pooled) metrics, as a JSON-ready dict."""
    check_dataset_predictor(predictor)  # before the files are read
    loaded = {Path(path): load_eval_scenes(path, config) for path in files}
    return evaluate_scenes(predictor, loaded, config, progress=progress, root=root)


def evaluate_scenes(
    predictor: Predictor,
    loaded: dict[Path, list[EvalScene]],
    config: EvalConfig = EvalConfig(),
    *,
    progress: bool | None = None,
    root: Path | None = None,
) -> dict:
    """``evaluate`` of files already read (``load_eval_scenes`` with the same ``config``), by their paths;
    ``progress``: a bar of the scenes (None: on a terminal only, so logs and pipes stay clean)."""
    check_dataset_predictor(predictor)
    if predictor.obs_len > config.obs_len:  # refused by the predictor at the first scene, in its API's words
        raise PredictorError(
            f"predictor {predictor.name!r} reads {predictor.obs_len} observed steps, the evaluation gives "
            f"{config.obs_len} of each scene ({config.obs_len} observed + {config.pred_len} predicted: "
            "TrajNet++'s protocol)"
        )
    per_file: dict[str, dict] = {}
    all_scores: list[SceneScore] = []
    with progress_bar(
        total=sum(len(s) for s in loaded.values()),
        desc=f"evaluating {predictor.name}",
        unit="scene",
        leave=False,
        show=progress,
    ) as bar:
        for path, scenes in loaded.items():
            scores = score_scenes(predictor, scenes, config, bar)
            key = str(path.relative_to(root)) if root is not None and path.is_relative_to(root) else str(path)
            per_file[key] = summarize(scores)
            all_scores.extend(scores)
    return {
        "predictor": predictor.name,
        "obs_len": config.obs_len,
        "steps_given": handed_steps(predictor, config.obs_len),
        "pred_len": config.pred_len,
        "top_k": config.top_k if config.top_k is not None and hasattr(predictor, "sample") else None,
        "files": per_file,
        "overall": summarize(all_scores),
    }


def format_table(result: dict) -> str:
    """The per-file and overall metrics as a plain-text table."""
    topk = result.get("top_k") is not None
    header = ["file", "scenes", "ADE [m]", "FDE [m]", "Col-I [%]", "Col-II [%]"]
    if topk:
        header += [f"top-{result['top_k']} ADE", f"top-{result['top_k']} FDE"]

    def row(name: str, m: dict) -> list[str]:
        if m["scenes"] == 0:
            return [name, "0"] + ["-"] * (len(header) - 2)
        cells = [
            name,
            str(m["scenes"]),
            f"{m['ade']:.3f}",
            f"{m['fde']:.3f}",
            _col_i_cell(m),
            f"{m['col_ii']:.2f}",
        ]
        if topk:
            cells += [f"{m['topk_ade']:.3f}", f"{m['topk_fde']:.3f}"]
        return cells

    rows = [row(name, m) for name, m in result["files"].items()]
    if len(result["files"]) > 1:
        rows.append(row("overall", result["overall"]))
    given, observed = result.get("steps_given", result["obs_len"]), result["obs_len"]
    window = f"the last {given} of {observed}" if given < observed else f"{observed}"
    title = (
        f"{result['predictor']}: {window} observed -> {result['pred_len']} predicted steps "
        "(TrajNet++ metrics, primary pedestrian)"
    )
    return "\n".join([title, *aligned_lines(header, rows), *_col_i_footnote(result, given)])


def _col_i_cell(metrics: dict) -> str:
    """Col-I, starred where it counts fewer scenes than the other columns (``_col_i_footnote``)."""
    if metrics["col_i"] is None:
        return "n/a"
    return f"{metrics['col_i']:.2f}" + ("*" if metrics["col_i_scenes"] < metrics["scenes"] else "")


def _col_i_footnote(result: dict, given: int) -> list[str]:
    """The line under the table that says what a starred Col-I counts: only the scenes whose every neighbour
    seen in the observed steps is in the last ``given`` ones, which the predictor reads and predicts."""
    if not any(m["scenes"] and m["col_i_scenes"] < m["scenes"] for m in result["files"].values()):
        return []
    overall = result["overall"]
    return [
        f"* Col-I of {overall['col_i_scenes']} of {overall['scenes']} scenes: those whose every neighbour "
        f"seen in the {result['obs_len']} observed steps is in the last {given}, which "
        f"{result['predictor']} reads (its config's obs_len) and predicts; ADE, FDE and Col-II are of every "
        "scene and neighbour"
    ]
