"""The data home: TRANSYNC_DATA, then ../shared/data (working directory, source checkout), then
the per-user cache; a variable that points nowhere is an error; absent data sets skip."""

import pytest

import transync.datasets._home as home_module
from transync.datasets import data_home


@pytest.fixture
def isolated(monkeypatch, tmp_path):
    """No TRANSYNC_DATA, a working directory without ../shared/data, an installed-copy layout
    (no checkout) and an empty cache location."""
    monkeypatch.delenv("TRANSYNC_DATA", raising=False)
    work = tmp_path / "a" / "work"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    monkeypatch.setattr(home_module, "_PACKAGE_ROOT", tmp_path / "site-packages")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path


def test_data_home_env(monkeypatch, tmp_path):
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    assert data_home() == tmp_path
    (tmp_path / "sub").mkdir()
    assert data_home(subfolder="sub") == tmp_path / "sub"
    assert data_home(required=False, subfolder="nope") is None
    with pytest.raises(FileNotFoundError, match="'nope'"):
        data_home(subfolder="nope")


def test_env_pointing_nowhere_is_an_error_not_a_fallback(monkeypatch, isolated):
    (isolated / "a" / "shared" / "data").mkdir(parents=True)      # a fallback that exists
    missing = isolated / "missing"
    monkeypatch.setenv("TRANSYNC_DATA", str(missing))
    for required in (True, False):
        with pytest.raises(FileNotFoundError, match=r"TRANSYNC_DATA=.*missing.* does not exist"):
            data_home(required=required)
    afile = isolated / "file.txt"
    afile.write_text("x")
    monkeypatch.setenv("TRANSYNC_DATA", str(afile))
    with pytest.raises(NotADirectoryError, match="is not a folder"):
        data_home(required=False)


def test_bad_arguments_and_empty_env_are_named(monkeypatch, isolated):
    """subfolder='/etc' left the data home; subfolder=5 raised "unsupported operand";
    required='no' counted as true; an unknown ~user raised pathlib's bare RuntimeError.
    TRANSYNC_DATA='' counts as unset, and the "not found" message says so."""
    (isolated / "a" / "shared" / "data").mkdir(parents=True)      # a fallback that exists
    monkeypatch.setenv("TRANSYNC_DATA", "")         # the shell convention: empty = unset
    assert data_home() == (isolated / "a" / "shared" / "data").resolve()
    monkeypatch.setenv("TRANSYNC_DATA", "~nosuchuser_x/data")
    with pytest.raises(ValueError, match=r"`TRANSYNC_DATA`: cannot expand '~nosuchuser_x/data'"):
        data_home()
    monkeypatch.delenv("TRANSYNC_DATA")
    with pytest.raises(ValueError, match="`subfolder` must be a folder inside the data home"):
        data_home(subfolder="/etc")
    with pytest.raises(ValueError, match="`subfolder` must be a folder inside the data home"):
        data_home(subfolder="../..")
    with pytest.raises(TypeError, match="`subfolder` must be None or a folder name"):
        data_home(subfolder=5)
    with pytest.raises(TypeError, match="`required` must be a bool, got str 'no'"):
        data_home(required="no")
    monkeypatch.setenv("TRANSYNC_DATA", "")
    with pytest.raises(FileNotFoundError, match=r"TRANSYNC_DATA is empty: taken as not set"):
        data_home(subfolder="nope")


def test_data_home_missing_names_every_place(isolated):
    assert data_home(required=False) is None
    with pytest.raises(FileNotFoundError, match="TRANSYNC_DATA not set") as exc:
        data_home()
    msg = str(exc.value)
    assert str((isolated / "a" / "shared" / "data").resolve()) in msg
    assert str(isolated / "cache" / "transync") in msg


def test_working_directory_then_checkout_then_cache(monkeypatch, isolated):
    cache = isolated / "cache" / "transync"
    cache.mkdir(parents=True)
    assert data_home() == cache.resolve()
    # a source checkout (pyproject.toml + src/transync) next to ../shared/data
    repo = isolated / "checkout" / "repo"
    (repo / "src" / "transync").mkdir(parents=True)
    (repo / "pyproject.toml").write_text("[project]\n")
    (isolated / "checkout" / "shared" / "data").mkdir(parents=True)
    monkeypatch.setattr(home_module, "_PACKAGE_ROOT", repo)
    assert data_home() == (isolated / "checkout" / "shared" / "data").resolve()
    # the working directory's ../shared/data comes first
    (isolated / "a" / "shared" / "data").mkdir(parents=True)
    assert data_home() == (isolated / "a" / "shared" / "data").resolve()


def test_installed_copy_does_not_look_beside_site_packages(isolated):
    # pip install: the package root is not a checkout, so its ../shared/data is not a candidate
    (isolated / "shared" / "data").mkdir(parents=True)
    assert data_home(required=False) is None


def test_cache_default_without_xdg(monkeypatch, isolated):
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(isolated / "home"))
    (isolated / "home" / ".cache" / "transync").mkdir(parents=True)
    assert data_home() == (isolated / "home" / ".cache" / "transync").resolve()


def test_empty_data_home_makes_data_tests_skip(monkeypatch, tmp_path, require_dataset):
    monkeypatch.setenv("TRANSYNC_DATA", str(tmp_path))
    with pytest.raises(pytest.skip.Exception, match="'oxford-graf' not found"):
        require_dataset("oxford-graf")
    (tmp_path / "oxford-graf").mkdir()                     # present but empty: still skipped
    with pytest.raises(pytest.skip.Exception):
        require_dataset("oxford-graf")
    (tmp_path / "oxford-graf" / "img1.ppm").write_bytes(b"P6")
    assert require_dataset("oxford-graf") == tmp_path / "oxford-graf"
