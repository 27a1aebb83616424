"""The compile cache's directory ($CROWDMPC_CACHE/compiled) checked where it is resolved: a file in its way
or a read-only place is one line naming $CROWDMPC_CACHE and what is wrong, never "not created yet" or an
error about a temporary file."""

from __future__ import annotations

import os
import pwd
from types import SimpleNamespace

import pytest

from mpc import cache_admin, cache_location
from mpc.errors import MPCConfigError
from tests.read_only import read_only_place  # noqa: F401 - a fixture


def test_a_file_for_the_cache_is_not_a_directory_for_writing_info_and_clear(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv(cache_location.CACHE_ENV, str(tmp_path / "file"))
    expected = (
        f"$CROWDMPC_CACHE={tmp_path / 'file'}: {tmp_path / 'file'} is not a directory; set $CROWDMPC_CACHE "
        "to a writable directory"
    )
    for use in (cache_location.writable_dir, cache_admin.info, cache_admin.clear):
        with pytest.raises(cache_location.CacheLocationError) as exc:
            use()
        assert str(exc.value) == expected
        assert isinstance(exc.value, MPCConfigError)  # the command line prints it as one line
    assert (tmp_path / "file").read_text() == "x"


def test_a_file_where_compiled_goes_is_named(tmp_path, monkeypatch):
    (tmp_path / "compiled").write_text("x")
    monkeypatch.setenv(cache_location.CACHE_ENV, str(tmp_path))
    with pytest.raises(
        cache_location.CacheLocationError, match=f"{tmp_path / 'compiled'} is not a directory"
    ):
        cache_admin.info()


def test_a_read_only_place_is_not_writable(read_only_place, monkeypatch):  # noqa: F811
    monkeypatch.setenv(cache_location.CACHE_ENV, str(read_only_place / "cache"))
    with pytest.raises(cache_location.CacheLocationError) as exc:
        cache_location.writable_dir()
    assert str(exc.value).startswith(
        f"$CROWDMPC_CACHE={read_only_place / 'cache'}: {read_only_place} is not writable ("
    )
    assert cache_admin.info().exists is False  # reading a cache that is not there is no error


def test_a_usable_cache_is_created_for_writing(tmp_path, monkeypatch):
    monkeypatch.setenv(cache_location.CACHE_ENV, str(tmp_path / "new"))
    assert cache_location.writable_dir() == tmp_path / "new" / "compiled"
    assert (tmp_path / "new" / "compiled").is_dir()


def test_an_explicit_directory_is_named_as_itself(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(cache_location.CacheLocationError) as exc:
        cache_location.writable_dir(tmp_path / "file" / "sub")
    assert (
        str(exc.value)
        == f"the compile cache {tmp_path / 'file' / 'sub'}: {tmp_path / 'file'} is not a directory"
    )


def test_a_path_the_shell_would_split_is_refused_before_anything_is_made(tmp_path, monkeypatch):
    # CasADi pastes the directory into gcc's command line unquoted: gcc would write to tmp_path/"my".
    monkeypatch.setenv(cache_location.CACHE_ENV, str(tmp_path / "my cache"))
    with pytest.raises(cache_location.CacheLocationError) as exc:
        cache_location.writable_dir()
    folder = tmp_path / "my cache" / "compiled"
    assert str(exc.value) == (
        f"$CROWDMPC_CACHE={tmp_path / 'my cache'}: its path {str(folder)!r} holds a space or shell "
        f"character, which CasADi passes to gcc unquoted; set $CROWDMPC_CACHE to {cache_location.SHELL_SAFE}"
    )
    assert isinstance(exc.value, MPCConfigError)
    assert list(tmp_path.iterdir()) == []  # not created


def test_a_path_that_is_not_utf8_is_refused_before_anything_is_made(tmp_path, monkeypatch):
    """CasADi receives a path holding undecodable bytes (surrogates in Python) as "": gcc's command lost its
    compiler ("sh: 1: -O2: not found") and every jit build failed, after the folder had been made."""
    root = os.fsdecode(bytes(tmp_path) + b"/c\xff")
    monkeypatch.setenv(cache_location.CACHE_ENV, root)
    with pytest.raises(cache_location.CacheLocationError) as exc:
        cache_location.writable_dir()
    assert str(exc.value) == (
        f"$CROWDMPC_CACHE={root}: its path {root + '/compiled'!r} is not UTF-8, which CasADi cannot pass to "
        f"gcc; set $CROWDMPC_CACHE to {cache_location.SHELL_SAFE}"
    )
    assert list(tmp_path.iterdir()) == []  # not created


def test_a_shell_character_reached_through_a_symlink_is_refused(tmp_path):
    (tmp_path / "a;b").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "a;b")
    with pytest.raises(cache_location.CacheLocationError, match="a;b/compiled.* holds a space or shell"):
        cache_location.writable_dir(tmp_path / "link" / "compiled")


def test_a_symlink_loop_is_named_as_no_directory(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(cache_location.CacheLocationError, match=f"{tmp_path / 'a'} is not a directory"):
        cache_location.writable_dir(tmp_path / "a" / "compiled")


@pytest.mark.parametrize("name", ["café", "a~b", "x=1,y%2@z+"])
def test_a_path_the_shell_takes_as_it_is_is_accepted(tmp_path, name):
    """shlex.quote's ASCII-only safe set refused /home/josé, where the default cache lives, and disabled
    every jit build; only what the shell splits on or interprets is refused."""
    assert cache_location.writable_dir(tmp_path / name) == tmp_path / name


@pytest.mark.parametrize(
    "cache, xdg, expected",
    [
        ("{tmp}/mine", "{tmp}/xdg", "{tmp}/mine"),  # $CROWDMPC_CACHE first
        (None, "{tmp}/xdg", "{tmp}/xdg/crowdmpc"),  # then the XDG spec's cache home (it was ignored)
        (None, "relative/xdg", "{home}/.cache/crowdmpc"),  # a relative one is invalid, the spec says
        (None, None, "{home}/.cache/crowdmpc"),
    ],
)
def test_the_compile_cache_and_the_prepared_data_share_one_root(tmp_path, monkeypatch, cache, xdg, expected):
    """Two functions find it (mpc imports nothing of predictors): they must agree, whatever is set."""
    from predictors.data.locate import cache_root

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    for variable, value in ((cache_location.CACHE_ENV, cache), ("XDG_CACHE_HOME", xdg)):
        if value is None:
            monkeypatch.delenv(variable, raising=False)
        else:
            monkeypatch.setenv(variable, value.format(tmp=tmp_path))
    root = expected.format(tmp=tmp_path, home=tmp_path / "home")
    assert str(cache_root()) == root and cache_location.cache_dir() == cache_root() / cache_location.SUBDIR


@pytest.mark.parametrize("home", ["", "relative/home"])
@pytest.mark.parametrize("cache, under", [(None, ".cache/crowdmpc"), ("~/mine", "mine"), ("~//mine", "mine")])
def test_a_home_that_is_no_absolute_path_is_passed_over_for_the_cache(
    tmp_path, monkeypatch, home, cache, under
):
    """Path.home() and expanduser take an empty $HOME for "/", so `env HOME= crowdmpc` run as root put the
    cache in /.cache/crowdmpc (or $CROWDMPC_CACHE="~/mine" in /mine), and a relative one in a folder of the
    current directory: both roots take the password database's home, as for no $HOME."""
    from predictors.data.locate import cache_root

    monkeypatch.setenv("HOME", home)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    if cache is None:
        monkeypatch.delenv(cache_location.CACHE_ENV, raising=False)
    else:
        monkeypatch.setenv(cache_location.CACHE_ENV, cache)
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=str(tmp_path / "pw")))
    assert cache_root() == tmp_path / "pw" / under
    assert cache_location.cache_dir() == tmp_path / "pw" / under / cache_location.SUBDIR


def test_no_home_at_all_is_one_line_naming_the_cache_variable(monkeypatch):
    from predictors.data.locate import cache_root
    from predictors.errors import PredictorError

    monkeypatch.setenv("HOME", "")
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.delenv(cache_location.CACHE_ENV, raising=False)
    monkeypatch.setattr(pwd, "getpwuid", lambda uid: SimpleNamespace(pw_dir=""))
    why = "(no absolute $HOME, and none in the password database); set $CROWDMPC_CACHE"
    with pytest.raises(PredictorError) as data:
        cache_root()
    with pytest.raises(cache_location.CacheLocationError) as compiled:
        cache_location.cache_dir()
    assert str(data.value) == f"cannot find the home directory for the cache {why}"
    assert str(compiled.value) == f"cannot find the home directory for the compile cache {why}"
    assert isinstance(compiled.value, MPCConfigError)  # the command line prints it as one line
    monkeypatch.setenv(cache_location.CACHE_ENV, "~/mine")
    with pytest.raises(PredictorError) as data:
        cache_root()
    with pytest.raises(cache_location.CacheLocationError) as compiled:
        cache_location.cache_dir()
    assert (
        str(data.value)
        == str(compiled.value)
        == (f"cannot find the home directory for $CROWDMPC_CACHE ~/mine {why} to an absolute path")
    )
    monkeypatch.setenv(cache_location.CACHE_ENV, "~no-such-user-here/mine")
    with pytest.raises(cache_location.CacheLocationError, match="^[^\n]*no such user"):
        cache_location.cache_dir()


def test_the_location_stays_importable_from_the_compile_cache():
    """Where the cache lives moved to mpc.cache_location; code written before imports it from here still."""
    from mpc import compile_cache, errors

    for name in ("CACHE_ENV", "SUBDIR", "cache_dir", "free_bytes", "readable_dir", "writable_dir"):
        assert getattr(compile_cache, name) is getattr(cache_location, name), name
    assert compile_cache.CacheLocationError is errors.CacheLocationError
    assert compile_cache.CompileCacheError is errors.CompileCacheError
