"""Recording closed-loop episodes to MCAP: one file per episode, an EpisodeObserver for the closed loop.

Log time = the episode's wall-clock start (metadata "episode" ``start_time_ns``, ns since the Unix epoch) +
its simulation time, so that Foxglove's clock shows when the run happened; the state, plan, prediction and
solver messages carry their simulation time too ("time", s, and "step"). Channels (JSON, schemas in
``pipelines.logs.schemas``):
  /robots, /humans      the state at t and the accelerations applied from t; the final state comes at the end
  /mpc/plan             each robot's planned positions t+1..t+H (controllers that plan)
  /mpc/prediction       the humans' predicted positions, per IBR iteration when asked (predicting controllers)
  /mpc/solver           status, wall time, IBR iterations, potential F_t, fallback
  /scene                foxglove.SceneUpdate: agents as spheres, goals, plans and predictions as line strips
                        (behind a sensor, a ring of its range per robot)
  /episode/metrics      once, at the end
Metadata records: "crowdmpc" (version, format), "episode" (seed, scenario, controller, predictor, checkpoint
sha256, sizes, start_time_ns, end_on_collision), "config" and "run" (JSON-encoded values).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from pipelines.errors import PipelineError
from pipelines.logs.identity import check_replaceable, run_identity
from pipelines.logs.names import episode_filename as episode_filename  # its callers import it from here
from pipelines.logs.reader import decode_metadata
from pipelines.logs.recorder import UNFINISHED_SUFFIX, McapRecorder
from pipelines.logs.scene import PLAN_DECIMALS, SceneBuilder, array_json
from pipelines.logs.schemas import (
    EPISODE_FORMAT,
    EPISODE_METRICS,
    HUMANS,
    PLAN,
    PREDICTION,
    ROBOTS,
    SCENE_UPDATE,
    SOLVER,
)
from pipelines.plain_json import plain
from pipelines.plugins import code_with_plugins

if TYPE_CHECKING:
    from crowdsim.env import Observation
    from pipelines.loop.controllers import ControlOutput
    from pipelines.loop.episode import EpisodeResult

FORMAT: Final[str] = EPISODE_FORMAT  # what this recorder writes (pipelines.logs.schemas says what it means)


def next_unseeded(out_dir: Path, scenario: str, written: int = -1) -> int:
    """The number of the next unseeded episode of ``scenario`` in ``out_dir``: one past the highest of its
    files there (``<scenario>_NNNNNN.mcap``, unfinished ``.part`` ones too) and ``written``, the highest this
    recorder wrote. Unlike a seed's, such a number names no scene: the same name may be another episode, so
    an unseeded episode never replaces a file."""
    pattern = re.compile(re.escape(scenario) + r"_(\d{6,})\.mcap(?:" + re.escape(UNFINISHED_SUFFIX) + ")?")
    numbers = [int(m.group(1)) for p in out_dir.iterdir() if (m := pattern.fullmatch(p.name))]
    return max([written, *numbers]) + 1


def _check_episode_files(path: Path, identity: Mapping[str, Any]) -> None:
    """Refuse to record to ``path`` when it or its unfinished ``.part`` (a killed run's, which ``crowdmpc
    review`` reads) holds another run's episode (``check_replaceable``)."""
    check_replaceable(path, identity)
    check_replaceable(path.with_name(path.name + UNFINISHED_SUFFIX), identity)


def seconds_to_ns(t: float) -> int:
    return int(round(t * 1e9))


def _metadata_strings(values: Mapping[str, Any]) -> dict[str, str]:
    """MCAP metadata holds strings only: every value JSON-encoded (``review`` decodes them back)."""
    return {str(k): json.dumps(plain(v), default=str) for k, v in values.items()}


class McapEpisodeRecorder:
    """An EpisodeObserver writing ``<out_dir>/<scenario>_seed<seed:06d>.mcap`` per episode, replacing the
    file of a rerun of the same run, finished or unfinished (``.part``: a killed run's), and refusing
    another run's (``run_identity``); ``<scenario>_<n:06d>.mcap`` for one no seed drew (a gym episode
    started from a layout), n one past the highest already in the folder, taken atomically, so recorders
    sharing a folder never write one file. Every episode handed to one recorder keeps its own file: the
    k-th one of a seed it already recorded (a gym loop resetting to that seed again) is
    ``<scenario>_seed<seed:06d>_<k>.mcap``, k = 1, 2, ..., under the same rule, so that running the same
    loop again replaces each of them. ``paths`` lists the files in order, each once.

    :param out_dir: folder for the files (created at the first episode if missing).
    :param record_iterations: also write the humans' prediction of every IBR iteration (when the controller
        keeps them: ``ControllerSpec(record_iterations=True)``).
    :param run_meta: facts about the whole run (command line, sweep cell...), stored in the "run" metadata.
    :param seeds: the seeds of every episode the run will record, when known: the first episode checks each
        one's file (``check_replaceable``), so that a folder holding another run's episode at a later seed
        is refused before any episode runs, not at that episode with the earlier ones' summary lost.
    """

    def __init__(
        self,
        out_dir: str | Path,
        *,
        record_iterations: bool = False,
        run_meta: Mapping[str, Any] | None = None,
        seeds: Iterable[int] = (),
        durable: bool = True,
    ):
        self.out_dir = Path(out_dir)
        self.durable = durable  # McapRecorder's: False for a scratch file that is copied, synced, elsewhere
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise PipelineError(f"--record needs a folder; {self.out_dir} is a file")
        self.record_iterations = record_iterations
        self.run_meta = dict(run_meta or {})
        self.paths: list[Path] = []  # every file started, in order
        self._recorder: McapRecorder | None = None
        self._cut: Path | None = None  # the file close() finished while its episode was still running
        self._scene: SceneBuilder | None = None
        self._last: Observation | None = None  # the newest state seen
        self._last_written_step = -1
        self._start_ns = 0  # the episode's wall-clock start, ns since the Unix epoch: log time at t = 0
        self._unseeded: dict[str, int] = {}  # scenario -> the number of its last episode with no seed
        self._repeats: dict[tuple[str, int], int] = {}  # (scenario, seed) -> episodes of it recorded so far
        self._planned = tuple(int(s) for s in seeds)  # checked at the first seeded episode, then dropped

    # -- EpisodeObserver -------------------------------------------------------------------------------------
    def on_reset(self, obs: Observation, meta: Mapping[str, Any]) -> None:
        self.close()  # an episode that ended without on_end (an exception in the loop) is finished as it is
        self._cut = None
        # made for the first episode, not before: a run refused first (a plugin's describe()) leaves no folder
        self.out_dir.mkdir(parents=True, exist_ok=True)
        missing = [key for key in ("seed", "scenario") if key not in meta]
        if missing:
            raise PipelineError(f"recording needs {missing} in the episode meta; got keys {sorted(meta)}")
        seed, scenario = None if meta["seed"] is None else int(meta["seed"]), str(meta["scenario"])
        n_robots, n_humans = len(obs.robot_positions), len(obs.human_positions)
        self._start_ns = time.time_ns()
        episode = {
            **({} if seed is None else {"seed": str(seed)}),  # none: no seed drew the episode
            "scenario": scenario,
            "controller": str(meta.get("controller", "")),
            "predictor": str(meta.get("predictor") or ""),
            "predictor_sha256": str(meta.get("predictor_sha256") or ""),
            "n_robots": str(n_robots),
            "n_humans": str(n_humans),
            "dt": repr(float(obs.dt)),
            "radius": repr(float(obs.radius)),
            "start_time_ns": str(self._start_ns),
        }
        # whether a contact ends the episode (contract.episode_meta): review tells by it a contact's end from
        # a loop's cut; an observer called by the user's own loop may be given no such key
        if "end_on_collision" in meta:
            episode["end_on_collision"] = json.dumps(bool(meta["end_on_collision"]))
        config = _metadata_strings(meta.get("config") or {})
        metadata = {
            # strings as they are (the version reads "0.1.0", not "\"0.1.0\""), the rest in JSON
            "crowdmpc": {
                **{k: v if isinstance(v, str) else json.dumps(v) for k, v in code_with_plugins().items()},
                "format": FORMAT,
            },
            "episode": episode,
            "config": config,
            "run": _metadata_strings(self.run_meta),
        }
        if seed is None:  # a number names no scene: never another episode's file
            self._recorder = self._claim_unseeded(scenario, metadata)
        else:  # the same scene: replaced when this run recorded it, in an earlier process
            repeat = self._repeats.get((scenario, seed), 0)
            path = self.out_dir / episode_filename(scenario, seed, repeat=repeat)
            identity = run_identity(episode, decode_metadata(config))
            planned, self._planned = self._planned, ()
            for other in planned:  # the run's identity is every episode's but for the seed
                _check_episode_files(self.out_dir / episode_filename(scenario, other), identity)
            _check_episode_files(path, identity)  # before the episode runs, and again as the recorder takes
            self._recorder = McapRecorder(  # each file (it holds the .part's lock then)
                path,
                metadata=metadata,
                may_replace=lambda p: check_replaceable(p, identity),
                durable=self.durable,
            )
            self._repeats[(scenario, seed)] = repeat + 1
        self.paths.append(self._recorder.path)
        from pipelines.loop.sensing import recorded_sensor_range  # not at import: it loads casadi

        sensor = recorded_sensor_range(meta.get("config"))  # behind a sensor: /scene draws its rings
        self._scene = SceneBuilder(n_robots, n_humans, float(obs.radius), sensor)
        self._last = obs
        self._last_written_step = -1

    def _claim_unseeded(self, scenario: str, metadata: Mapping[str, Mapping[str, str]]) -> McapRecorder:
        """The file of the next free number, taken atomically (``McapRecorder(new=True)``): another recorder
        writing into the folder at the same moment may take a number first, and this one moves past it. The
        folder is listed for a scenario's first file and after such a clash only (a listing per episode made
        a gym run's recording quadratic in its files: 14 ms an episode at 10 000)."""
        last = self._unseeded.get(scenario)
        number = next_unseeded(self.out_dir, scenario) if last is None else last + 1
        while True:  # ends: every clash moves past a taken number
            try:
                recorder = McapRecorder(
                    self.out_dir / episode_filename(scenario, None, number),
                    metadata=metadata,
                    new=True,
                    durable=self.durable,
                )
            except FileExistsError:
                number = next_unseeded(self.out_dir, scenario, number)
                continue
            self._unseeded[scenario] = number
            return recorder

    def on_step(self, obs: Observation, out: ControlOutput, next_obs: Observation) -> None:
        rec = self._require_open()
        builder, _ = self._require_episode()
        t_ns = self._start_ns + seconds_to_ns(obs.time)
        stamp = {"time": float(obs.time), "step": int(obs.step)}
        self._write_state(
            rec, obs, t_ns, stamp, next_obs.robot_last_actions.tolist(), out.accelerations.tolist()
        )
        plan = None if out.plan is None else np.asarray(out.plan, dtype=float)
        prediction = None if out.prediction is None else np.asarray(out.prediction, dtype=float)
        head = f'{{"time":{float(obs.time)!r},"step":{int(obs.step)},"positions":'
        if plan is not None:
            rec.write_json(
                "/mpc/plan", f"{head}{array_json(plan, PLAN_DECIMALS)}}}".encode(), t_ns, schema=PLAN
            )
        if prediction is not None:
            iterations = ",".join(
                array_json(np.asarray(p, dtype=float), PLAN_DECIMALS)
                for p in (out.iteration_predictions if self.record_iterations else ())
            )
            text = f'{head}{array_json(prediction, PLAN_DECIMALS)},"iterations":[{iterations}]}}'
            rec.write_json("/mpc/prediction", text.encode(), t_ns, schema=PREDICTION)
        solver = {
            **stamp,
            "status": str(out.status),
            "solve_time_s": float(out.solve_time_s),
            "iterations": int(out.iterations),
            "potential": plain(out.potential),
            "fallback": out.fallback,
            "extra": plain(out.extra) if out.extra else {},
        }
        rec.write("/mpc/solver", solver, t_ns, schema=SOLVER)
        scene = builder.update(
            t_ns,
            obs.robot_positions,
            obs.robot_goals,
            obs.human_positions,
            plan,
            prediction,
            obs.human_present,
        )
        rec.write_json("/scene", scene, t_ns, schema=SCENE_UPDATE)
        self._last = next_obs

    def on_end(self, result: EpisodeResult) -> None:
        if self._recorder is None and self._cut is not None:
            # closed mid-episode (``with`` ended before the env's close ended a cut episode): the file stands
            # as one cut short, which review names; raising here stopped the env's close
            self._cut = None
            return
        rec = self._require_open()
        builder, last = self._require_episode()
        t_ns = self._start_ns + seconds_to_ns(last.time)
        if last.step > self._last_written_step:  # the terminal state, reached by the last step
            self._write_state(rec, last, t_ns, {"time": float(last.time), "step": int(last.step)}, None, None)
            scene = builder.update(
                t_ns,
                last.robot_positions,
                last.robot_goals,
                last.human_positions,
                None,
                None,
                last.human_present,
            )
            rec.write_json("/scene", scene, t_ns, schema=SCENE_UPDATE)
        rec.write("/episode/metrics", episode_summary(result), t_ns, schema=EPISODE_METRICS)
        self.close()
        self._cut = None

    # -- lifetime --------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Finish the open file, if any (also what ``with McapEpisodeRecorder(...)`` does on the way out)."""
        if self._recorder is not None:
            recorder, self._recorder = self._recorder, None
            self._cut = recorder.path
            recorder.close()

    def __enter__(self) -> McapEpisodeRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def written_line(self, finished: int) -> str:
        """What was recorded, for a run whose first ``finished`` episodes ended. An episode cut short (Ctrl-C)
        keeps its file, without metrics but named as a whole one's: said, as ``review`` says it."""
        cut = [path.name for path in self.paths[finished:]]  # one file per episode, in order
        note = f"; {', '.join(cut)}: cut short, no metrics" if cut else ""
        return f"wrote {len(self.paths)} MCAP file(s) to {self.out_dir}{note}"

    # -- helpers ---------------------------------------------------------------------------------------------
    def _require_open(self) -> McapRecorder:
        if self._recorder is None and self._cut is not None:
            raise PipelineError(f"McapEpisodeRecorder: on_step after close(), which finished {self._cut}")
        if self._recorder is None:
            raise PipelineError("McapEpisodeRecorder: on_step/on_end called before on_reset")
        return self._recorder

    def _require_episode(self) -> tuple[SceneBuilder, Observation]:
        """The scene builder and newest state, which on_reset sets together with the open file."""
        if self._scene is None or self._last is None:
            raise PipelineError("McapEpisodeRecorder: on_step/on_end called before on_reset")
        return self._scene, self._last

    def _write_state(
        self,
        rec: McapRecorder,
        obs: Observation,
        t_ns: int,
        stamp: dict[str, Any],
        actions: list | None,
        commanded: list | None,
    ) -> None:
        robots = {
            **stamp,
            "positions": obs.robot_positions.tolist(),
            "velocities": obs.robot_velocities.tolist(),
            "goals": obs.robot_goals.tolist(),
            "actions": actions,
            "commanded": commanded,
            "reached": obs.robot_reached.tolist(),
        }
        rec.write("/robots", robots, t_ns, schema=ROBOTS)
        humans = {
            **stamp,
            "positions": obs.human_positions.tolist(),
            "velocities": obs.human_velocities.tolist(),
            "goals": obs.human_goals.tolist(),
        }
        if obs.human_present is not None:
            humans["present"] = obs.human_present.tolist()
        rec.write("/humans", humans, t_ns, schema=HUMANS)
        self._last_written_step = int(obs.step)


def episode_summary(result: EpisodeResult) -> dict[str, Any]:
    """The /episode/metrics message: the closed loop's ``EpisodeRecord``, as every report serialises it."""
    return result.record().to_dict()
