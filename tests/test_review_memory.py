"""benchmarks/review_memory.py: the folder's copies, and the figures of one small run."""

import json

from tests.benchmark_modules import load_benchmark

review_memory = load_benchmark("review_memory")


def test_fill_copies_the_sources_in_turn_up_to_the_count(tmp_path):
    sources = []
    for name in ("a.mcap", "b.mcap"):
        (tmp_path / name).write_bytes(name.encode())
        sources.append(tmp_path / name)
    review_memory.fill(tmp_path, sources, 5)
    files = sorted(tmp_path.glob("*.mcap"))
    assert len(files) == 5
    copies = sorted(p for p in files if p.name.startswith("copy"))
    assert [p.name for p in copies] == ["copy000002_a.mcap", "copy000003_b.mcap", "copy000004_a.mcap"]
    assert [p.read_bytes() for p in copies] == [b"a.mcap", b"b.mcap", b"a.mcap"]
    review_memory.fill(tmp_path, sources, 3)  # it holds more already: nothing removed, nothing added
    assert len(list(tmp_path.glob("*.mcap"))) == 5


def test_a_small_run_reports_each_process_peak(tmp_path, capsys):
    out = tmp_path / "m.json"
    assert review_memory.main(["--files", "3", "--episodes", "1", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    (row,) = report["rows"]
    assert row["files"] == 3 and report["file_kb"] > 0
    # every process loads the interpreter and the reader; reading adds to it
    assert report["interpreter_mb"] > 0
    assert row["review_peak_mb"] >= 0.9 * report["interpreter_mb"]
    assert row["held_peak_mb"] >= 0.9 * report["interpreter_mb"]
    assert "episodes recorded: 1," in capsys.readouterr().out


def test_fewer_files_than_recorded_episodes_is_refused(capsys):
    """The folder holds every recorded episode, so a row of 2 files over 4 recordings would review 4 and
    divide by 2."""
    import pytest

    with pytest.raises(SystemExit) as stop:
        review_memory.main(["--files", "2", "--episodes", "4"])
    assert stop.value.code == 2
    assert "--files 2: at least --episodes (4) files are reviewed" in capsys.readouterr().err


def test_a_childs_peak_is_its_own_not_this_processs():
    """ru_maxrss of a child on Linux starts at the peak of the process it was forked from: every figure was
    floored at the script's own peak (a DMPC+LSTM recording made a fresh interpreter read 347 MB)."""
    held = b"\x01" * (256 * 2**20)  # this process's peak above 256 MB, every page touched
    mb, seconds, read_from = review_memory.peak("")
    assert len(held) and seconds > 0
    assert read_from in review_memory.PEAK_SOURCES
    if read_from == "VmHWM":  # Linux; with ru_maxrss alone (no /proc) the floor is what the header says
        assert 0 < mb < 128  # a bare interpreter: tens of MB


def test_a_repeated_file_count_is_refused_as_the_other_benchmarks_refuse_it(capsys):
    """--files 20 20 measured 20 once and said nothing; the other benchmarks' lists refuse a repeat."""
    import pytest

    with pytest.raises(SystemExit) as stop:
        review_memory.main(["--files", "4", "6", "4", "--episodes", "1"])
    assert stop.value.code == 2
    assert "--files names 4 more than once" in capsys.readouterr().err
