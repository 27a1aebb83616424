"""pipelines/experiments/cells.py on its own: the order of a sweep's episodes, the swap table's lists
(pipelines/experiments/methods.py), and the paper's count of episodes, by hand."""

import pytest

from pipelines.config.settings import SweepSettings
from pipelines.errors import PipelineError
from pipelines.experiments.cells import Experiment, cell_groups, get_experiment
from pipelines.experiments.methods import LATER_SWAP_PREDICTORS, SWAP_PREDICTORS, swap_predictors
from pipelines.experiments.worker import EpisodeWorker
from pipelines.loop.controllers import ControllerSpec


def test_tasks_run_episode_index_by_episode_index_across_the_cells():
    """Table II at 5 humans, 3 episodes a cell from seed 4: every cell runs episode 0 (circle, seed 4), then
    episode 1 (perpendicular, seed 4), then episode 2 (circle, seed 5); a sweep stopped early has run the same
    crowds in every cell."""
    tasks = get_experiment("table2").tasks(3, humans=(5,), seed=4)
    got = [(t.index, t.cell.method, t.scenario, t.seed) for t in tasks]
    assert got == [
        (0, "CMPC", "circle", 4),
        (0, "DMPC", "circle", 4),
        (1, "CMPC", "perpendicular", 4),
        (1, "DMPC", "perpendicular", 4),
        (2, "CMPC", "circle", 5),
        (2, "DMPC", "circle", 5),
    ]


def test_a_worker_builds_each_cell_once_in_a_sweep_of_more_cells_than_it_keeps(monkeypatch):
    """Tasks interleaved across more cells than a worker keeps controllers built (CONTROLLER_CACHE) made it
    rebuild most of them for every episode: a replayed crowd's at 20 people is ~300 MB and seconds to prepare
    (27 replayed cells, 108 episodes, docs/replayed_crowds.md: 140 s, 88-92 s grouped). Grouped by the cache,
    each cell's controller is built once, and every episode still runs, each once."""
    monkeypatch.setattr("pipelines.experiments.worker.CONTROLLER_CACHE", 3)
    tasks = get_experiment("baselines").tasks(2, humans=(5, 6))  # 4 constant-velocity cells: 2 groups of 2
    assert len({t.cell.key for t in tasks}) == 4
    worker = EpisodeWorker()
    outcomes = [worker.run(t) for t in tasks]
    assert all(o.error is None for o in outcomes)
    assert worker.builds == 4  # interleaved across the 4 cells, every one of the 8 episodes built one
    assert sorted(t.key for t in tasks) == sorted(
        t.key for t in get_experiment("baselines").tasks(2, humans=(5, 6))
    )


def test_cells_are_grouped_evenly_and_only_past_the_cache():
    cells = list(range(21))
    assert [len(g) for g in cell_groups(cells, 16)] == [11, 10]
    assert [x for g in cell_groups(cells, 16) for x in g] == cells
    assert cell_groups(cells, 21) == [cells]
    assert [len(g) for g in cell_groups(cells, 5)] == [5, 4, 4, 4, 4]
    assert [len(g) for g in cell_groups(cells[:20], 5)] == [5, 5, 5, 5]


def test_crowd_sizes_run_and_report_smallest_first_whatever_their_order():
    """``--humans 6,5`` gave the 6-human rows first in cells.csv, episodes.csv and episodes.jsonl; 5,6 runs
    the same episodes, and table.md and the plots go by crowd size."""
    table2 = get_experiment("table2")
    assert table2.cells((6, 5)) == table2.cells((5, 6))
    assert [c.n_humans for c in table2.cells((7, 5, 6))] == [5, 5, 6, 6, 7, 7]
    assert table2.tasks(2, humans=(6, 5)) == table2.tasks(2, humans=(5, 6))


def test_a_predictor_named_twice_is_refused_naming_it():
    predictors = get_experiment("predictors")
    with pytest.raises(PipelineError, match=r"--predictors names \['constant_velocity'\] more than once"):
        predictors.with_predictors(["constant_velocity", "social_lstm_eth", "constant_velocity"])
    assert [label for label, _ in predictors.with_predictors(["a", "b"]).methods] == ["a", "b"]


def test_the_default_swap_table_has_the_later_models_a_zoo_has():
    assert LATER_SWAP_PREDICTORS == {"social_gru_eth", "social_attention_eth"}
    without = swap_predictors()
    assert without == tuple(n for n in SWAP_PREDICTORS if n not in LATER_SWAP_PREDICTORS)
    with_gru = swap_predictors({"social_gru_eth", "unrelated"})
    assert with_gru == tuple(n for n in SWAP_PREDICTORS if n != "social_attention_eth")


def test_a_sweep_runs_the_papers_episodes_per_cell_by_default():
    # Section VI: 500 circle + 500 perpendicular crossing episodes in each cell of Tables II and III.
    assert SweepSettings().episodes_per_cell == 1000


def test_a_sweep_seed_must_fit_the_toml_config_it_is_written_into():
    assert SweepSettings(seed=2**63 - 1, episodes_per_cell=2).seed == 2**63 - 1  # seeds: seed + i // 2
    with pytest.raises(PipelineError, match=r"seed must be at most 2\*\*63 - 1 \(TOML's largest integer\)"):
        SweepSettings(seed=2**63)
    # and so must its last episode's: 1000 a cell reach seed + 499
    assert SweepSettings(seed=2**63 - 500).seed == 2**63 - 500
    with pytest.raises(PipelineError, match=rf"seed must be at most {2**63 - 500} with 1000 episodes a cell"):
        SweepSettings(seed=2**63 - 499)


def test_an_experiment_needs_distinct_labels_and_some_humans():
    # Two columns of one label would share a cell key, and so their episodes' records.
    spec = ControllerSpec("orca")
    with pytest.raises(PipelineError, match=r"needs distinct method labels, got \['A', 'A'\]"):
        Experiment("x", "X", methods=(("A", spec), ("A", spec)), humans=(5,))
    with pytest.raises(PipelineError, match=r"humans must be numbers of humans in 1\.\.50, got \(\)"):
        Experiment("x", "X", methods=(("A", spec),), humans=())


def test_swapped_lists_take_every_setting_but_the_swapped_one_from_the_first_method():
    """with_controllers and with_predictors build each column from the experiment's first method: here
    constant velocity with flocking off, not the second method's Social-LSTM with flocking on."""
    first = ControllerSpec("cmpc", "constant_velocity", flocking=False)
    second = ControllerSpec("dmpc", "social_lstm_eth", flocking=True)
    methods = (("first", first), ("second", second))
    controllers = Experiment("c", "C", methods=methods, humans=(5,), controller_list=True)
    assert controllers.with_controllers(["orca", "dmpc"]).methods == (
        ("orca", ControllerSpec("orca", "constant_velocity", flocking=False)),
        ("dmpc", ControllerSpec("dmpc", "constant_velocity", flocking=False)),
    )
    predictors = Experiment("p", "P", methods=methods, humans=(5,), predictor_list=True)
    assert predictors.with_predictors(["social_gan_eth"]).methods == (
        ("social_gan_eth", ControllerSpec("cmpc", "social_gan_eth", flocking=False)),
    )


def test_the_controllers_title_names_a_predictor_only_while_a_column_predicts():
    """``--controllers orca straight``'s table.md was titled "..., those that predict the humans with the
    paper's predictor", of columns that predict nothing; with a --predictor as well, that name."""
    experiment = get_experiment("controllers")
    assert experiment.with_controllers(["orca", "straight"]).title == "Controllers: each controller"
    assert experiment.with_controllers(["straight", "dmpc"]).title == experiment.title
    swapped = experiment.with_controllers(["orca"]).with_predictor("constant_velocity")
    assert swapped.title == "Controllers: each controller"
    swapped = experiment.with_predictor("constant_velocity").with_controllers(["cmpc"])
    assert swapped.title.endswith(", those that predict the humans with constant_velocity")
    assert swapped.with_controllers(["orca"]).title == "Controllers: each controller"


def test_an_empty_list_of_controllers_is_refused_naming_the_experiment():
    with pytest.raises(PipelineError, match=r"^experiment 'controllers' needs at least one controller$"):
        get_experiment("controllers").with_controllers([])


def test_the_coupling_experiment_compares_couplings_with_one_predictor():
    """IBR and both NLP columns plan with the soft-pooling Social-LSTM (the one with a useful gradient for
    the NLP): only the coupling differs between the columns."""
    specs = [spec for _, spec in get_experiment("coupling").methods]
    assert [s.predictor for s in specs] == ["social_lstm_soft_eth"] * 3
    assert [s.coupling for s in specs] == ["ibr", "nlp", "nlp"]


def test_controllers_that_predict_nothing_keep_no_margins_after_with_margins():
    """with_margins, then with_controllers: ORCA's and the straight line's columns took the first method's
    margins, which with_margins' own rule leaves off a method that predicts nothing (its cell key said so)."""
    from pipelines.loop.margins import MarginSpec, parse_margins

    margins = parse_margins("conformal:0.1")
    experiment = get_experiment("controllers").with_margins(margins)
    experiment = experiment.with_controllers(["cmpc", "orca", "straight"])
    kept = {label: spec.margins for label, spec in experiment.methods}
    assert kept == {"cmpc": margins, "orca": MarginSpec(), "straight": MarginSpec()}


@pytest.mark.parametrize("name", ["table2", "conventions"])
def test_an_experiment_pickles_and_copies(name):
    """A notebook running a sweep in a background process (``multiprocessing``'s spawn pickles the
    SweepConfig), or ``copy.deepcopy`` of a config: "cannot pickle 'mappingproxy' object" (the paper's
    figures and the per-method worlds). Back from the pickle, an experiment is equal and still read-only."""
    import copy
    import pickle
    from types import MappingProxyType

    from pipelines.experiments.cells import EXPERIMENTS

    experiment = EXPERIMENTS[name]
    for back in (pickle.loads(pickle.dumps(experiment)), copy.deepcopy(experiment)):
        assert back == experiment
        assert isinstance(back.paper, MappingProxyType) and isinstance(back.method_worlds, MappingProxyType)
