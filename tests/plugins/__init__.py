"""Predictor plugins the tests register (``crowdmpc --plugin tests.plugins.toy_predictor:ToyNet``), and an
installed distribution declaring entry points, as pip leaves one."""

from __future__ import annotations

from pathlib import Path

DISTRIBUTION = "shadow-pkg"


def install_distribution(monkeypatch, folder: Path, entry_points: str) -> None:
    """The distribution ``shadow-pkg`` 1.0 installed in ``folder`` (put first on sys.path), declaring the
    entry points of ``entry_points`` (entry_points.txt: ``[group]`` then ``name = module:Class`` lines)."""
    info = folder / "shadow_pkg-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {DISTRIBUTION}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(entry_points)
    monkeypatch.syspath_prepend(str(folder))
