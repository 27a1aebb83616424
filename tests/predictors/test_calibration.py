import dataclasses
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from predictors import manifest, zoo
from predictors.calibration import Calibration, calibrate_real, calibration_from_errors
from predictors.calibration_store import (
    CALIBRATIONS_FORMAT,
    CALIBRATIONS_NAME,
    find_calibration,
    read_calibrations,
    save_calibration,
)
from predictors.conformal import (
    check_alpha,
    conformal_quantile,
    conformal_rank,
    coverage,
    min_samples,
    step_counts,
    step_quantiles,
)
from predictors.constant_velocity import ConstantVelocity
from predictors.data.prepare import prepare_ewap
from predictors.errors import PredictorError, UnknownPredictor
from predictors.real_data import real_data_sha256, real_errors, validation_files
from tests.predictors.samples import STEP, scene, track, write_lines, write_tiny_ewap, write_walk_file

SHA_A = "a" * 64
SHA_B = "b" * 64
DATA = "d" * 64
NAN = math.nan


# ---------------------------------------------------------------------------------------------- statistics
def test_conformal_quantile_by_hand():
    scores = np.arange(10, 0, -1, dtype=float)  # 1..10, unsorted on purpose
    assert conformal_quantile(scores, 0.1) == 10.0  # rank ceil(11 * 0.9) = 10
    assert conformal_quantile(scores, 0.2) == 9.0  # rank ceil(11 * 0.8) = 9
    assert conformal_quantile(scores, 0.5) == 6.0  # rank ceil(5.5) = 6


def test_a_rank_that_is_an_integer_is_not_rounded_up_by_binary_rounding():
    # n = 9, alpha = 0.7: (n + 1)(1 - alpha) = 3 exactly, but 10 * (1.0 - 0.7) is 3.0000000000000004 in
    # floating point; the rank is 3 (the third smallest of 1..9), not 4.
    assert conformal_quantile(np.arange(9.0, 0.0, -1.0), 0.7) == 3.0


def test_too_few_samples_give_infinity():
    assert conformal_quantile(np.arange(1.0, 6.0), 0.1) == math.inf  # rank ceil(6 * 0.9) = 6 > 5
    assert conformal_quantile(np.array([]), 0.1) == math.inf
    assert min_samples(0.1) == 9 and min_samples(0.2) == 4 and min_samples(0.05) == 19
    assert conformal_quantile(np.arange(1.0, 10.0), 0.1) == 9.0  # n = 9 is just enough


def test_an_alpha_near_one_takes_the_smallest_score_not_the_largest():
    """(n + 1)(1 - alpha) below the old fixed slack of 1e-9 made the rank 0, and index -1 read the largest
    score: the widest margin for the loosest alpha. The rank is at least 1."""
    scores = np.arange(100.0, 0.0, -1.0)
    assert conformal_rank(100, 0.99999999999999) == 1
    assert conformal_quantile(scores, 0.99999999999999) == 1.0
    assert conformal_quantile(scores, 0.9999999) == 1.0
    assert conformal_rank(0, 0.5) == 1  # no scores: rank 1 > 0, infinity


@pytest.mark.parametrize(("n", "alpha"), [(2, 0.3333333333), (9, 0.0999999999), (99, 0.00999999999)])
def test_an_alpha_written_with_many_digits_gets_its_exact_rank(n, alpha):
    """ceil((n + 1)(1 - alpha)) just above n means too few samples: the fixed slack rounded it down to n,
    a finite margin the definition does not give. min_samples agrees with the rank."""
    assert conformal_rank(n, alpha) == n + 1
    assert conformal_quantile(np.arange(1.0, n + 1), alpha) == math.inf
    assert min_samples(alpha) == n + 1 and conformal_rank(n + 1, alpha) == n + 1


@pytest.mark.parametrize("alpha", [0.01, 0.05, 0.1, 0.2, 0.5, 0.7, 0.45, 0.1234567, 0.99999999999999, 1e-12])
def test_min_samples_is_the_fewest_with_a_finite_rank(alpha):
    fewest = min_samples(alpha)
    if fewest < 10**6:
        assert conformal_rank(fewest, alpha) <= fewest
    assert conformal_rank(fewest - 1, alpha) > fewest - 1


@pytest.mark.parametrize(
    ("n", "alpha", "rank"),
    # the shipped blocks' alphas at their sample counts (checkpoints/calibrations.json), by hand, and counts
    # where (n + 1)(1 - alpha) is an integer, which binary rounding must not push one sample up
    [
        (11700, 0.01, 11584),  # 11701 * 0.99 = 11583.99
        (532, 0.05, 507),  # 533 * 0.95 = 506.35
        (482, 0.1, 435),  # 483 * 0.9 = 434.7
        (22263, 0.2, 17812),  # 22264 * 0.8 = 17811.2
        (10726, 0.5, 5364),  # 10727 * 0.5 = 5363.5
        (99, 0.01, 99),
        (19, 0.05, 19),
        (9, 0.1, 9),
        (4, 0.2, 4),
        (1, 0.5, 1),
        (9, 0.7, 3),
    ],
)
def test_the_ranks_of_the_shipped_alphas_are_unchanged(n, alpha, rank):
    assert conformal_rank(n, alpha) == rank


SHIPPED_ALPHAS = (0.01, 0.05, 0.1, 0.2, 0.5)  # checkpoints/README.md's calibrate commands


def test_every_shipped_predictor_has_the_blocks_the_checkpoints_readme_lists():
    """checkpoints/README.md: closed-loop blocks for every shipped predictor, constant velocity and the
    oracle included, and real ones for all but the oracle, each for the weights the manifest holds.
    social_gru_eth and social_attention_eth had no real blocks: `--margins conformal:0.1:real` failed."""
    from predictors.calibration_store import read_calibration_file
    from predictors.registry import PREDICTORS

    shipped = Path(__file__).resolve().parents[2] / "checkpoints"
    weights = {name: e.sha256 for name, e in zoo.read_manifest(shipped).items()}
    weights |= dict.fromkeys(PREDICTORS)  # built-ins: no weights
    blocks = {b.key(): b for b in read_calibration_file(shipped / CALIBRATIONS_NAME)}
    for name, sha in weights.items():
        for source in ("closed-loop", "real") if name != "orca_oracle" else ("closed-loop",):
            for alpha in SHIPPED_ALPHAS:
                block = blocks.get((name, source, alpha, None, True))  # the shipped: every human seen
                assert block is not None, f"no shipped {source} block of {name} at alpha {alpha}"
                assert block.predictor_sha256 == sha, f"{name}'s {source} block is of other weights"


def test_an_alpha_too_small_for_any_calibration_is_refused_in_one_line():
    """min_samples(1e-309) overflowed (1 / alpha is inf) into a traceback; below 1e-12 no calibration can
    have the samples, and alphas that close are one calibration key."""
    assert min_samples(1e-12) == 10**12 - 1
    for tiny in (1e-309, 5e-324, 1e-13):
        for call in (min_samples, check_alpha, lambda a: conformal_rank(10, a)):
            with pytest.raises(PredictorError, match=r"alpha must be at least 1e-12 .*got "):
                call(tiny)


@pytest.mark.parametrize("alpha", [0.0, 1.0, -0.1, 1.5, True, "0.1"])
def test_alpha_must_lie_strictly_between_zero_and_one(alpha):
    with pytest.raises(PredictorError, match="0 < alpha < 1"):
        conformal_quantile(np.ones(20), alpha)


@pytest.mark.parametrize("bad", [-1.0, math.inf, NAN])
def test_scores_must_be_finite_and_non_negative(bad):
    with pytest.raises(PredictorError, match="finite and non-negative"):
        conformal_quantile(np.array([1.0, bad]), 0.5)


def test_step_quantiles_use_each_columns_known_entries():
    errors = np.full((10, 2), NAN)
    errors[:, 0] = np.arange(1.0, 11.0)
    errors[:4, 1] = [0.4, 0.1, 0.3, 0.2]  # step 2 known for four samples only
    assert step_counts(errors) == (10, 4)
    assert step_quantiles(errors, 0.2) == (9.0, 0.4)  # ranks ceil(11 * 0.8) = 9 and ceil(5 * 0.8) = 4
    assert step_quantiles(errors, 0.1) == (10.0, math.inf)  # four samples are too few at alpha 0.1


def test_errors_must_be_a_matrix_of_distances():
    with pytest.raises(PredictorError, match=r"shape \(n, H\)"):
        step_quantiles(np.ones(5), 0.1)
    with pytest.raises(PredictorError, match="non-negative distances"):
        step_quantiles(np.array([[1.0, -0.5]]), 0.1)
    with pytest.raises(PredictorError, match=r"shape \(n, H\) with H >= 1, got \(3, 0\)"):
        step_quantiles(np.zeros((3, 0)), 0.1)  # no horizon step: no margin to plan with


def test_coverage_by_hand():
    errors = np.array([[0.1, 0.5], [0.2, NAN], [0.3, 0.7], [0.4, 0.9]])
    assert coverage(errors, (0.2, 0.7)) == (0.5, pytest.approx(2 / 3))
    assert coverage(errors, [1.0, 0.1]) == (1.0, 0.0)
    assert math.isnan(coverage(np.full((2, 1), NAN), (1.0,))[0])  # nothing to cover
    with pytest.raises(PredictorError, match="1 quantiles for errors of 2 horizon steps"):
        coverage(errors, (1.0,))
    with pytest.raises(PredictorError, match="3 quantiles for errors of 2 horizon steps"):
        coverage(errors, (1.0, 1.0, 1.0))
    # rounding is no miss: constant velocity's zero errors come out as 1e-16 m, its margin at alpha 0.5 as
    # 2.5e-16 m; an error a micrometre past a margin is one
    rounded = np.array([[0.0], [1.1e-16], [3.3e-16], [6.6e-16], [1e-6]])
    assert coverage(rounded, (2.5e-16,)) == (0.8,)


def test_held_out_coverage_on_exchangeable_data():
    """Split conformal on i.i.d. data: mean held-out coverage is ceil((n+1)(1-a))/(n+1) >= 1 - a."""
    rng = np.random.default_rng(7)
    alpha, n_cal, n_test, trials = 0.1, 99, 500, 300
    shares = []
    for _ in range(trials):
        scale = np.array([0.1, 0.2, 0.3, 0.4])  # errors grow with the horizon step
        cal = np.abs(rng.normal(size=(n_cal, 4))) * scale
        test = np.abs(rng.normal(size=(n_test, 4))) * scale
        shares.append(coverage(test, step_quantiles(cal, alpha)))
    mean = np.mean(shares, axis=0)
    assert np.all(mean >= 1 - alpha - 0.01)
    assert np.all(mean <= 1 - alpha + 1 / (n_cal + 1) + 0.01)  # and not much more than asked for


# -------------------------------------------------------------------------------------------- the block
def block(**changes) -> Calibration:
    values = dict(
        predictor="social_lstm_eth",
        predictor_sha256=SHA_A,
        source="real",
        alpha=0.1,
        n=(100, 98, 95, 90),
        quantiles=(0.1, 0.25, 0.4, 0.6),
        data_sha256=DATA,
        details={"files": {"val/biwi_eth.ndjson": SHA_B}},
        created="2026-11-30T12:00:00+00:00",
    )
    values.update(changes)
    return Calibration(**values)


def test_block_json_round_trip():
    original = block()
    text = json.dumps(original.to_json())
    assert Calibration.from_json(json.loads(text), "here") == original
    assert original.horizon == 4


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"predictor": ""}, "'predictor' must be a non-empty name"),
        ({"predictor_sha256": "abc"}, "'predictor_sha256' must be 64 lowercase hex"),
        ({"source": "sim"}, r"'source' must be one of \['real', 'closed-loop'\], got 'sim'"),
        ({"alpha": 0.0}, "'alpha' must be a number with 0 < alpha < 1"),
        ({"n": (100, 98)}, "4 quantiles but 2 sample counts"),
        (  # no finite quantile at alpha 0.1 comes of fewer than 9 (a block claiming none was planned with)
            {"n": (100, 98, 8, 90)},
            r"'n' \[100, 98, 8, 90\]: a finite quantile at alpha=0.1 takes at least 9 samples a step",
        ),
        ({"n": (1, -2, 3, 4)}, "'n' must be a non-empty list of sample counts"),
        ({"quantiles": (0.1, math.inf, 0.3, 0.4)}, "'quantiles' must be a list of finite non-negative"),
        ({"data_sha256": "x"}, "'data_sha256' must be 64 lowercase hex"),
        ({"details": {"x": object()}}, "'details' is not plain JSON"),
        ({"created": "yesterday"}, "'created' must be an ISO 8601 time, got 'yesterday'"),
    ],
)
def test_block_validation(changes, message):
    with pytest.raises(PredictorError, match=message):
        block(**changes)


def test_from_json_names_where_and_what():
    values = block().to_json()
    del values["quantiles"]
    with pytest.raises(PredictorError, match=r"^f.json: calibration 'social_lstm_eth' lacks \['quantiles'\]"):
        Calibration.from_json(values, "f.json")
    values = block().to_json() | {"alpha": 2}
    with pytest.raises(PredictorError, match=r"^f.json: calibration 'alpha' must be"):
        Calibration.from_json(values, "f.json")
    with pytest.raises(PredictorError, match="must be lists"):
        Calibration.from_json(block().to_json() | {"n": 5}, "f.json")


def test_calibration_from_errors_refuses_too_few_samples():
    errors = np.full((10, 2), NAN)
    errors[:, 0] = np.arange(1.0, 11.0)
    errors[:4, 1] = 0.5
    made = calibration_from_errors(
        errors, predictor="p", predictor_sha256=None, source="closed-loop", alpha=0.2, data_sha256=DATA
    )
    assert made.n == (10, 4) and made.quantiles == (9.0, 0.5) and made.source == "closed-loop"
    with pytest.raises(PredictorError, match=r"alpha=0.1 at horizon step\(s\) \[2\].*need at least 9"):
        calibration_from_errors(
            errors, predictor="p", predictor_sha256=None, source="closed-loop", alpha=0.1, data_sha256=DATA
        )


# ------------------------------------------------------------------------------------------------- storage
def test_storage_round_trip_and_replacement(tmp_path):
    assert read_calibrations(tmp_path) == []
    first, other_alpha, other_source = block(), block(alpha=0.05), block(source="closed-loop")
    for b in (first, other_alpha, other_source):
        path = save_calibration(b, tmp_path)
    assert path == tmp_path / CALIBRATIONS_NAME
    document = json.loads(path.read_text())
    assert document["format"] == CALIBRATIONS_FORMAT and document["version"] == 1
    # stored sorted by (predictor, source, alpha), whatever the order of saving
    assert read_calibrations(tmp_path) == [other_source, other_alpha, first]

    newer = block(alpha=0.1 + 1e-15, quantiles=(0.2, 0.3, 0.5, 0.7))  # the same alpha, to 1e-12
    save_calibration(newer, tmp_path)
    stored = read_calibrations(tmp_path)
    assert len(stored) == 3 and newer in stored and first not in stored
    assert not list(tmp_path.glob(".*.tmp"))  # the temp file was renamed into place


def test_a_failed_storage_write_leaves_the_file_and_no_temporary(tmp_path):
    """A full disk left the half-written ``.calibrations.json.PID.tmp`` in the zoo for good."""
    from tests.read_only import file_size_limit

    save_calibration(block(), tmp_path)
    before = (tmp_path / CALIBRATIONS_NAME).read_bytes()
    with file_size_limit(100), pytest.raises(OSError, match="File too large"):  # as a full disk fails
        save_calibration(block(alpha=0.05), tmp_path)
    assert (tmp_path / CALIBRATIONS_NAME).read_bytes() == before
    assert not list(tmp_path.glob(".*.tmp"))


def test_storage_sits_beside_the_manifest_and_leaves_it_alone(tmp_path):
    manifest = tmp_path / zoo.MANIFEST_NAME
    manifest.write_text('{"format": "crowdmpc-zoo", "version": 1, "models": []}\n')
    before = manifest.read_bytes()
    assert save_calibration(block(), tmp_path) == tmp_path / CALIBRATIONS_NAME
    assert manifest.read_bytes() == before
    assert read_calibrations(tmp_path) == [block()]


def test_user_calibrations_go_to_the_user_zoo_and_shipped_ones_are_read_only_defaults(tmp_path, monkeypatch):
    shipped, user = tmp_path / "shipped", tmp_path / "user"
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(shipped))
    monkeypatch.setenv(zoo.ZOO_ENV, str(user))
    save_calibration(block(), shipped)  # as shipped: alpha 0.1 and 0.2
    save_calibration(block(alpha=0.2), shipped)
    shipped_bytes = (shipped / CALIBRATIONS_NAME).read_bytes()
    assert read_calibrations() == [block(), block(alpha=0.2)]  # no user file yet: the shipped defaults

    mine = block(quantiles=(0.5, 0.6, 0.7, 0.8), predictor_sha256=SHA_B)  # the user's own, same key as one
    assert save_calibration(mine) == user / CALIBRATIONS_NAME
    assert (shipped / CALIBRATIONS_NAME).read_bytes() == shipped_bytes
    assert read_calibrations(user) == [mine]  # the user file holds the user's block only
    assert read_calibrations() == [mine, block(alpha=0.2)]  # the user's replaces the shipped one
    assert find_calibration("social_lstm_eth", "real", 0.1, sha256=SHA_B) == mine
    assert find_calibration("social_lstm_eth", "real", 0.2, sha256=SHA_A) == block(alpha=0.2)
    with pytest.raises(PredictorError, match=f"{user / CALIBRATIONS_NAME}: the real calibration"):
        find_calibration("social_lstm_eth", "real", 0.1, sha256=SHA_A)  # the file named is the user's
    with pytest.raises(
        PredictorError, match=f"in {user / CALIBRATIONS_NAME} or {shipped / CALIBRATIONS_NAME}"
    ):
        find_calibration("social_lstm_eth", "real", 0.05, sha256=SHA_A)

    monkeypatch.setenv(zoo.ZOO_ENV, str(shipped))  # a user zoo that is the shipped one: never written
    with pytest.raises(PredictorError, match="read-only"):
        save_calibration(block(alpha=0.3))
    assert (shipped / CALIBRATIONS_NAME).read_bytes() == shipped_bytes
    assert read_calibrations() == [block(), block(alpha=0.2)]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{not json", "not valid JSON"),
        (
            '{"format": "crowdmpc-zoo", "version": 1}',
            'not a crowdmpc calibrations file .*"crowdmpc-calibrations"',
        ),
        ('{"format": "crowdmpc-calibrations", "version": 2}', 'unsupported "version" 2, expected 1'),
        # a bool and a float where the version, an int, is meant were taken for version 1
        ('{"format": "crowdmpc-calibrations", "version": true}', 'unsupported "version" True, expected 1'),
        ('{"format": "crowdmpc-calibrations", "version": 1.0}', 'unsupported "version" 1.0, expected 1'),
        (
            '{"format": "crowdmpc-calibrations", "version": "' + "9" * 100 + '"}',
            'unsupported "version" \'9{56}\\.\\.\\., expected 1',
        ),
        ('{"format": "crowdmpc-calibrations", "version": 1, "calibrations": {}}', "must be a list of blocks"),
        ('{"format": "crowdmpc-calibrations", "version": 1, "calibrations": [3]}', r"calibrations\[0\]: a "),
    ],
)
def test_malformed_file_is_explained(tmp_path, text, message):
    (tmp_path / CALIBRATIONS_NAME).write_text(text)
    with pytest.raises(PredictorError, match=f"{CALIBRATIONS_NAME}.*{message}"):
        read_calibrations(tmp_path)


@pytest.mark.parametrize(
    ("make", "kind"),
    [
        (lambda path: path.mkdir(), "a directory"),
        (os.mkfifo, "a FIFO"),
        (lambda path: path.symlink_to(path.parent / "nowhere"), "a symbolic link to nothing"),
    ],
    ids=["directory", "fifo", "broken-link"],
)
def test_a_user_calibrations_file_that_is_no_file_is_refused_not_taken_for_absent(
    tmp_path, monkeypatch, make, kind
):
    """A directory, FIFO or broken link at the user zoo's calibrations.json was read as no file: every run
    used the shipped blocks in silence, and calibrate replaced the FIFO. Each read, and a store, now refuses
    it in one line naming it (a FIFO is never opened: the read would wait for a writer)."""
    shipped, user = tmp_path / "shipped", tmp_path / "user"
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(shipped))
    monkeypatch.setenv(zoo.ZOO_ENV, str(user))
    save_calibration(block(), shipped)
    user.mkdir()
    path = user / CALIBRATIONS_NAME
    make(path)
    expected = f"^{path}: not a regular file \\({kind}\\); the zoo's calibrations are read from a JSON file"
    with pytest.raises(PredictorError, match=expected):
        read_calibrations()
    with pytest.raises(PredictorError, match=expected):
        find_calibration("social_lstm_eth", "real", 0.1, sha256=SHA_A)
    with pytest.raises(PredictorError, match=expected):
        save_calibration(block(alpha=0.2))
    assert os.path.lexists(path) and not path.is_file()  # left as it was


def test_bad_block_and_duplicates_in_the_file_are_explained(tmp_path):
    path = tmp_path / CALIBRATIONS_NAME
    bad = block().to_json() | {"source": "sim"}
    path.write_text(json.dumps({"format": CALIBRATIONS_FORMAT, "version": 1, "calibrations": [bad]}))
    with pytest.raises(PredictorError, match=r"calibrations\[0\]: calibration 'source' must be one of"):
        read_calibrations(tmp_path)
    twice = [block().to_json(), block().to_json()]
    path.write_text(json.dumps({"format": CALIBRATIONS_FORMAT, "version": 1, "calibrations": twice}))
    with pytest.raises(PredictorError, match=r"calibrations\[1\] repeats predictor 'social_lstm_eth'"):
        read_calibrations(tmp_path)


def behind(sensor_range: float | None, **changes) -> Calibration:
    """A closed-loop block made behind a sensor of ``sensor_range`` m (None: every human in view)."""
    details = {"episodes": 200} | ({} if sensor_range is None else {"sensor_range": sensor_range})
    return block(source="closed-loop", details=details, **changes)


def test_blocks_behind_different_sensors_stand_side_by_side_and_a_run_takes_its_own_view(tmp_path):
    """One block per (predictor, source, alpha, sensor range): a calibration behind a 3 m sensor no longer
    replaces the one made with every human in view. A run takes the block of its own view, else the one
    with every human in view, else the nearest range (seeing everyone: the longest)."""
    for made in (None, 3.0, 5.0):
        save_calibration(behind(made, quantiles=(0.1, 0.2, 0.3, made or 0.4)), tmp_path)
    assert [b.sensor_range for b in read_calibrations(tmp_path)] == [None, 3.0, 5.0]  # file order
    assert save_calibration(behind(3.0), tmp_path)  # a recalibration behind 3 m replaces that block alone
    assert [b.quantiles[-1] for b in read_calibrations(tmp_path)] == [0.4, 0.6, 5.0]

    def planned(wanted: float | None, directory=tmp_path) -> float | None:
        found = find_calibration("social_lstm_eth", "closed-loop", 0.1, directory, SHA_A, wanted)
        return found.sensor_range

    assert [planned(r) for r in (None, 3.0, 5.0, 4.0, 2.0)] == [None, 3.0, 5.0, None, None]
    only_sensors = tmp_path / "sensors"
    only_sensors.mkdir()
    for made in (3.0, 5.0):
        save_calibration(behind(made), only_sensors)
    assert [planned(r, only_sensors) for r in (None, 3.5, 4.5, 4.0, 9.0)] == [5.0, 3.0, 5.0, 3.0, 5.0]
    stale = tmp_path / "stale"
    save_calibration(behind(3.0, predictor_sha256=SHA_B), stale)
    with pytest.raises(PredictorError) as changed:
        find_calibration("social_lstm_eth", "closed-loop", 0.1, stale, SHA_A, 3.0)
    assert "calibration at alpha=0.1 behind a 3 m sensor of predictor 'social_lstm_eth'" in str(changed.value)
    assert str(changed.value).endswith("--alpha 0.1 --sensor-range 3")  # the command remakes that block


def test_a_sensor_range_must_be_a_distance_of_a_closed_loop_block(tmp_path):
    for bad in (0, -1.0, math.inf, "3", True):
        with pytest.raises(PredictorError, match="'details.sensor_range' must be a finite number of metres"):
            behind(bad)  # type: ignore[arg-type]
    with pytest.raises(
        PredictorError, match="'details.sensor_range' is for closed-loop blocks, this one is 'real'"
    ):
        block(details={"sensor_range": 3.0})
    twice = [behind(3.0).to_json(), behind(3.0).to_json(), behind(None).to_json()]
    path = tmp_path / CALIBRATIONS_NAME
    path.write_text(json.dumps({"format": CALIBRATIONS_FORMAT, "version": 1, "calibrations": twice}))
    with pytest.raises(
        PredictorError, match=r"calibrations\[1\] repeats .* alpha=0.1 behind a 3 m sensor; keep"
    ):
        read_calibrations(tmp_path)
    path.write_text(json.dumps({"format": CALIBRATIONS_FORMAT, "version": 1, "calibrations": twice[1:]}))
    assert [b.sensor_range for b in read_calibrations(tmp_path)] == [3.0, None]


def test_find_calibration(tmp_path):
    save_calibration(block(), tmp_path)
    save_calibration(block(alpha=0.2), tmp_path)
    assert find_calibration("social_lstm_eth", "real", 0.1, tmp_path, sha256=SHA_A) == block()
    with pytest.raises(PredictorError) as missing:
        find_calibration("social_lstm_eth", "closed-loop", 0.1, tmp_path, sha256=SHA_A)
    assert "\n" not in str(missing.value)
    assert str(missing.value).startswith(
        "no closed-loop calibration at alpha=0.1 for predictor 'social_lstm_eth' in "
    )
    assert str(missing.value).endswith(
        "; run: crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.1"
    )
    with pytest.raises(PredictorError, match=r"\(it has alpha 0.1, 0.2\); run: crowdmpc calibrate"):
        find_calibration("social_lstm_eth", "real", 0.05, tmp_path, sha256=SHA_A)


def test_advice_names_an_alpha_of_many_digits_exactly(tmp_path):
    """The advice printed alpha with :g (6 digits): 0.1234567 became --alpha 0.123457, a block that never
    matches 0.1234567 (keys match within 1e-12). Following the advice now makes the block asked for."""
    from predictors.calibration_store import recalibrate_command

    command = recalibrate_command("constant_velocity", "closed-loop", 0.1234567)
    assert command.endswith("--alpha 0.1234567")
    with pytest.raises(PredictorError) as missing:
        find_calibration("social_lstm_eth", "real", 0.1234567, tmp_path, sha256=SHA_A)
    assert "alpha=0.1234567 " in str(missing.value) and str(missing.value).endswith("--alpha 0.1234567")
    made = block(alpha=float(str(missing.value).rsplit(" ", 1)[1]))
    save_calibration(made, tmp_path)
    assert find_calibration("social_lstm_eth", "real", 0.1234567, tmp_path, sha256=SHA_A) == made
    with pytest.raises(PredictorError, match=r"\(it has alpha 0.1234567\)"):
        find_calibration("social_lstm_eth", "real", 0.5, tmp_path, sha256=SHA_A)


def test_find_calibration_refuses_other_weights(tmp_path):
    save_calibration(block(), tmp_path)
    with pytest.raises(PredictorError) as stale:
        find_calibration("social_lstm_eth", "real", 0.1, tmp_path, sha256=SHA_B)
    message = str(stale.value)
    assert f"made for weights sha256 {SHA_A}, but the weights now have sha256 {SHA_B}" in message
    assert "weights changed since calibration, recalibrate: crowdmpc calibrate --predictor" in message


@pytest.mark.parametrize("asked", [None, 3.0])
def test_a_stale_block_made_beyond_the_sensor_range_bound_quotes_a_command_calibrate_runs(tmp_path, asked):
    """A block stored behind a 2000 m sensor before crowdsim.world.SENSOR_RANGE's 1000 m, its weights changed
    since: the refusal quoted `--sensor-range 2000`, a command calibrate refuses now. It quotes the command of
    the view asked for (whose block is planned with first) and says why; a block within the bound, its own."""
    save_calibration(block(source="closed-loop", details={"sensor_range": 2000.0}), tmp_path)
    save_calibration(block(source="closed-loop", alpha=0.2, details={"sensor_range": 3.0}), tmp_path)
    with pytest.raises(PredictorError) as stale:
        find_calibration("social_lstm_eth", "closed-loop", 0.1, tmp_path, sha256=SHA_B, sensor_range=asked)
    sensor = "" if asked is None else " --sensor-range 3"
    assert str(stale.value).endswith(
        "recalibrate: crowdmpc calibrate --predictor social_lstm_eth --source closed-loop --alpha 0.1"
        f"{sensor}; the block was made behind a 2000 m sensor before calibrate bounded the range (the sensor "
        "range must be at most 1000 m, got 2000.0) and cannot be made again: the command makes one of the "
        "view asked for, planned with before it"
    )
    with pytest.raises(PredictorError) as own:
        find_calibration("social_lstm_eth", "closed-loop", 0.2, tmp_path, sha256=SHA_B, sensor_range=asked)
    assert str(own.value).endswith("--alpha 0.2 --sensor-range 3")


def test_find_calibration_reads_the_current_weights_from_the_zoo(tmp_path):
    entry = zoo.ZooEntry(
        "social_lstm_eth", "SocialLSTMPredictor", "social_lstm", "w.pt", SHA_A, "w.json", SHA_B, "paper"
    )
    manifest.write_manifest({entry.name: entry}, tmp_path)
    save_calibration(block(), tmp_path)
    save_calibration(block(predictor="constant_velocity", predictor_sha256=None), tmp_path)
    assert find_calibration("social_lstm_eth", "real", 0.1, tmp_path).predictor_sha256 == SHA_A
    assert find_calibration("constant_velocity", "real", 0.1, tmp_path).predictor_sha256 is None
    manifest.write_manifest({entry.name: dataclasses.replace(entry, sha256=SHA_B)}, tmp_path)  # retrained
    with pytest.raises(PredictorError, match="weights changed since calibration"):
        find_calibration("social_lstm_eth", "real", 0.1, tmp_path)
    save_calibration(block(predictor="gone"), tmp_path)
    with pytest.raises(UnknownPredictor, match="unknown predictor 'gone'"):
        find_calibration("gone", "real", 0.1, tmp_path)


# ---------------------------------------------------------------------------------------------- real data
def stopping_scene_file(path):
    """A 21-step scene (primary 1) whose last six steps, 15..20, are what obs_len 2 + horizon 4 keep.

    1 walks +x at 0.5 m/step throughout; 2 walks beside it and stops at step 16 (the last observed one);
    3 walks at y = 3 until step 18, then leaves; 4 is seen at step 15 only, so not at the last observed step.
    """
    records = [scene(0, 1, 0, 20 * STEP)]
    for k in range(21):
        f = k * STEP
        records.append(track(f, 1, 0.5 * k, 0.0))
        records.append(track(f, 2, 0.5 * min(k, 16), 1.0))
        if k <= 18:
            records.append(track(f, 3, 0.25 * k, 3.0))
        if k == 15:
            records.append(track(f, 4, 9.0, 9.0))
    return write_lines(path, records)


@pytest.mark.parametrize("obs_len", [2, 9])
def test_real_errors_by_hand(tmp_path, obs_len):
    path = stopping_scene_file(tmp_path / "stop.ndjson")
    errors = real_errors(ConstantVelocity(obs_len=obs_len), [path], horizon=4)
    # agents in order of appearance: walker 0 m; stopper overshoots by k x 0.5 m; leaver 0 m then unknown
    expected = np.array([[0.0, 0.0, 0.0, 0.0], [0.5, 1.0, 1.5, 2.0], [0.0, 0.0, NAN, NAN]])
    np.testing.assert_allclose(errors, expected, atol=1e-9)


def test_real_errors_count_each_person_and_time_once(tmp_path):
    # two scenes over the same frames (primaries 1 and 2): the same two people, at the same times
    path = write_walk_file(tmp_path / "walk.ndjson")
    errors = real_errors(ConstantVelocity(), [path], horizon=4)
    np.testing.assert_allclose(errors, np.zeros((2, 4)), atol=1e-9)
    # two files are two sequences: rows from each count, however alike
    other = write_walk_file(tmp_path / "other.ndjson")
    assert real_errors(ConstantVelocity(), [path, other], horizon=4).shape == (4, 4)
    with pytest.raises(PredictorError, match="horizon must be a positive number of steps"):
        real_errors(ConstantVelocity(), [path], horizon=0)


def test_real_data_sha256_names_and_contents(tmp_path):
    a = write_walk_file(tmp_path / "val" / "a.ndjson")
    b = stopping_scene_file(tmp_path / "val" / "b.ndjson")
    digest = real_data_sha256([a, b], tmp_path)
    assert digest == real_data_sha256([b, a], tmp_path)  # order does not matter
    assert digest != real_data_sha256([a, b])  # names do: "a.ndjson" is not "val/a.ndjson"
    b.write_text(b.read_text().replace('"x": 0.0', '"x": 0.01', 1))
    assert digest != real_data_sha256([a, b], tmp_path)
    c = write_walk_file(tmp_path / "test" / "a.ndjson")
    with pytest.raises(PredictorError, match="both named 'a.ndjson'"):
        real_data_sha256([a, c])


def test_calibrate_real_on_prepared_validation_files(tmp_path):
    prepared = tmp_path / "prepared"
    prepare_ewap(write_tiny_ewap(tmp_path / "data"), prepared, categorize_scenes=False, log=lambda msg: None)
    files = validation_files(prepared)
    names = ["val/biwi_eth.ndjson", "val/biwi_hotel.ndjson"]
    assert [p.relative_to(prepared).as_posix() for p in files] == names
    blocks, errors = calibrate_real(ConstantVelocity(), files, [0.1, 0.2], root=prepared)
    assert errors.shape[1] == 4 and errors.shape[0] >= 9
    assert [b.alpha for b in blocks] == [0.1, 0.2]
    for b in blocks:
        assert b.predictor == "constant_velocity" and b.predictor_sha256 is None and b.source == "real"
        assert b.n == step_counts(errors) and b.quantiles == step_quantiles(errors, b.alpha)
        assert b.data_sha256 == real_data_sha256(files, prepared)
        assert sorted(b.details["files"]) == names
        assert all(c >= 1 - b.alpha for c in coverage(errors, b.quantiles))  # in-sample, so it must hold
    save_calibration(blocks[0], tmp_path)
    assert find_calibration("constant_velocity", "real", 0.1, tmp_path, sha256=None) == blocks[0]


def _save_alphas(directory: str, alphas: list[float], start) -> None:
    start.wait()  # all at once
    for alpha in alphas:  # a new block each time: one lost write loses it for good
        save_calibration(block(alpha=alpha), directory)


def test_parallel_calibrations_keep_every_block(tmp_path):
    """Each save reads the file, replaces its own block and writes it back: without the zoo's lock two
    writers that read the same old file each wrote back only their own block."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    start = context.Event()
    # alphas from 0.02: block()'s 90 samples give no finite quantile below 1/91
    shares = [[round(0.02 + 0.001 * (40 * k + i), 3) for i in range(40)] for k in range(4)]
    workers = [context.Process(target=_save_alphas, args=(str(tmp_path), a, start)) for a in shares]
    for w in workers:
        w.start()
    start.set()
    for w in workers:
        w.join(timeout=120)
    assert [w.exitcode for w in workers] == [0] * len(shares)
    assert sorted(b.alpha for b in read_calibrations(tmp_path)) == sorted(sum(shares, []))


def test_a_repeated_key_is_found_among_other_predictors_and_sources(tmp_path):
    """Blocks are compared within their (predictor, source) only (every earlier block was, quadratic in the
    blocks); a key repeated with other blocks between, and alpha within the tolerance, is still refused."""
    path = tmp_path / CALIBRATIONS_NAME
    blocks = [
        block(),
        block(source="closed-loop"),
        block(predictor="vanilla_lstm_eth"),
        block(alpha=0.2),
        block(alpha=0.1 + 5e-13),
    ]
    path.write_text(
        json.dumps(
            {"format": CALIBRATIONS_FORMAT, "version": 1, "calibrations": [b.to_json() for b in blocks]}
        )
    )
    with pytest.raises(
        PredictorError, match=r"calibrations\[4\] repeats predictor 'social_lstm_eth', source 'real'"
    ):
        read_calibrations(tmp_path)
    path.write_text(
        json.dumps(
            {"format": CALIBRATIONS_FORMAT, "version": 1, "calibrations": [b.to_json() for b in blocks[:4]]}
        )
    )
    assert read_calibrations(tmp_path) == blocks[:4]


def test_a_block_made_without_track_lengths_stands_beside_the_tracked_one_and_is_taken_by_its_view(tmp_path):
    """`calibrate --sensor-range 3 --no-sensor-tracks`: keyed apart from the tracked 3 m block; a run behind
    a tracker that reports no track lengths takes it, and without it the tracked block of its range, before
    the full view's."""
    untracked = behind(3.0, quantiles=(0.9, 0.9, 0.9, 0.9))
    untracked = dataclasses.replace(untracked, details={**untracked.details, "sensor_tracks": False})
    assert untracked.key()[3:] == (3.0, False) and behind(3.0).key()[3:] == (3.0, True)
    for made in (behind(None), behind(3.0), untracked):
        save_calibration(made, tmp_path)
    assert len(read_calibrations(tmp_path)) == 3

    def planned(wanted: float | None, tracks: bool, directory=tmp_path) -> tuple[float | None, bool]:
        found = find_calibration("social_lstm_eth", "closed-loop", 0.1, directory, SHA_A, wanted, tracks)
        return found.key()[3:]

    assert planned(3.0, False) == (3.0, False) and planned(3.0, True) == (3.0, True)
    assert planned(4.0, False) == (None, True)  # another range: the full view, as before
    tracked_only = tmp_path / "tracked"
    for made in (behind(None), behind(3.0)):
        save_calibration(made, tracked_only)
    assert planned(3.0, False, tracked_only) == (3.0, True)  # its range, the track lengths the other way
    with pytest.raises(PredictorError, match="'details.sensor_tracks' must be true or false"):
        dataclasses.replace(untracked, details={**untracked.details, "sensor_tracks": "no"})
    with pytest.raises(PredictorError, match="and false only beside a sensor_range"):
        block(source="closed-loop", details={"sensor_tracks": False})
