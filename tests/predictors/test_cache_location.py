"""The data cache ($CROWDMPC_CACHE) checked before prepared data is written there, and data directories that
are no directories named for what they are."""

from __future__ import annotations

import pytest

from predictors.data import locate
from predictors.data.locate import prepared_dir, resolve_data_dir, writable_cache_dir
from predictors.data.prepare import prepare_ewap
from predictors.errors import PredictorError
from tests.predictors.samples import write_tiny_ewap
from tests.read_only import read_only_place  # noqa: F401 - a fixture


def test_a_file_for_the_cache_is_not_a_directory(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv(locate.CACHE_ENV, str(tmp_path / "file"))
    with pytest.raises(PredictorError) as exc:
        writable_cache_dir("prepared")
    assert str(exc.value) == (
        f"$CROWDMPC_CACHE={tmp_path / 'file'}: {tmp_path / 'file'} is not a directory; set $CROWDMPC_CACHE "
        "to a writable directory"
    )


def test_a_read_only_cache_is_not_writable(read_only_place, monkeypatch):  # noqa: F811
    monkeypatch.setenv(locate.CACHE_ENV, str(read_only_place / "cache"))
    with pytest.raises(PredictorError) as exc:
        writable_cache_dir("prepared")
    assert str(exc.value).startswith(
        f"$CROWDMPC_CACHE={read_only_place / 'cache'}: {read_only_place} is not writable ("
    )


def test_raw_data_is_not_prepared_into_an_unusable_cache(tmp_path, monkeypatch):
    raw_root = tmp_path / "data"
    write_tiny_ewap(raw_root)
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv(locate.CACHE_ENV, str(tmp_path / "file"))

    def prepare(*args, **kwargs):
        raise AssertionError("preparing into an unusable cache")

    monkeypatch.setattr(locate, "prepare_ewap", prepare)
    with pytest.raises(PredictorError, match=r"^\$CROWDMPC_CACHE=.* is not a directory"):
        prepared_dir(raw_root, log=lambda msg: None, progress=False)


def test_data_prepared_in_the_cache_is_read_without_writing(tmp_path, monkeypatch):
    raw_root = tmp_path / "data"
    write_tiny_ewap(raw_root)
    monkeypatch.setenv(locate.CACHE_ENV, str(tmp_path / "cache"))

    def fast_prepare(*args, **kwargs):
        return prepare_ewap(*args, **{**kwargs, "categorize_scenes": False, "references": {}})

    monkeypatch.setattr(locate, "prepare_ewap", fast_prepare)
    first = prepared_dir(raw_root, log=lambda msg: None, progress=False)

    def unwritable(*parts):
        raise AssertionError("checked for writing")

    monkeypatch.setattr(locate, "writable_cache_dir", unwritable)
    assert prepared_dir(raw_root, log=lambda msg: None, progress=False) == first


def test_a_data_dir_that_is_a_file_a_loop_or_missing_says_which(tmp_path):
    (tmp_path / "file").write_text("x")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    for name, what in (
        ("file", "is not a directory"),
        ("loop", "is a symbolic-link loop"),
        ("absent", "does not exist"),
    ):
        with pytest.raises(PredictorError) as exc:
            resolve_data_dir(tmp_path / name)
        assert str(exc.value) == f"data directory {tmp_path / name} {what}"
