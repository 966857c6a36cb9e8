"""Output folders as one unit: whole or not at all, replaced whole, refused before any work, usual permissions."""

import json
import os
import stat

import pytest

from fmvmg_sim.cli.main import main
from fmvmg_sim.errors import InputError
from fmvmg_sim.output import MARKER, OutputFolder, check_output_folder, format_bytes, output_folder


def _mode(p):
    return stat.S_IMODE(os.stat(p).st_mode)


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def _siblings(path):
    return sorted(p.name for p in path.parent.iterdir() if p.name != path.name)


def test_the_folder_appears_only_when_the_block_ends(tmp_path):
    out = tmp_path / "run"
    with output_folder(out, command="test") as tmp:
        (tmp / "a.txt").write_text("a")
        assert not out.exists() and tmp.parent == tmp_path  # beside -o, on the same file system
    assert (out / "a.txt").read_text() == "a"
    marker = json.loads((out / MARKER).read_text())
    assert marker["command"] == "test" and marker["files"] == ["a.txt"]
    assert _siblings(out) == []  # no temporary folder left


def test_a_second_run_replaces_the_first_whole(tmp_path):
    out = tmp_path / "run"
    with output_folder(out) as tmp:
        (tmp / "old_plot.png").write_text("x")
        (tmp / "record.csv").write_text("1")
    with output_folder(out) as tmp:
        (tmp / "record.csv").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "record.csv"]
    assert (out / "record.csv").read_text() == "2"
    assert _siblings(out) == []


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_a_failed_or_interrupted_run_leaves_the_old_folder(tmp_path, exc):
    out = tmp_path / "run"
    with output_folder(out) as tmp:
        (tmp / "record.csv").write_text("old")
    with pytest.raises(exc):
        with output_folder(out) as tmp:
            (tmp / "record.csv").write_text("half")
            raise exc()
    assert (out / "record.csv").read_text() == "old"
    assert _siblings(out) == []


def test_a_failed_first_run_leaves_nothing(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with output_folder(out) as tmp:
            (tmp / "record.csv").write_text("half")
            raise RuntimeError
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_staged_folder_never_committed_is_discarded(tmp_path):
    staged = OutputFolder(tmp_path / "run")
    (staged.path / "x").write_text("x")
    del staged  # collected: the temporary folder goes
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fail", [False, True])
def test_in_place_writes_the_final_folder_and_puts_the_old_one_back_on_failure(tmp_path, fail):
    out = tmp_path / "bench"
    with output_folder(out, in_place=True) as tmp:
        (tmp / "scores.json").write_text("old")
    staged = OutputFolder(out, in_place=True)
    assert staged.path == out.absolute() and not (out / "scores.json").exists()
    (staged.path / "scores.json").write_text("new")
    if fail:
        staged.discard()
        assert (out / "scores.json").read_text() == "old"
    else:
        staged.commit()
        assert (out / "scores.json").read_text() == "new"
    assert _siblings(out) == []


def test_a_folder_of_other_files_is_never_replaced(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not an fmvmg output folder"):
        OutputFolder(tmp_path)
    assert (tmp_path / "notes.txt").read_text() == "mine"
    OutputFolder(tmp_path / "empty_is_fine").discard()


def test_a_file_and_an_unwritable_parent_are_refused(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(InputError, match="not a folder"):
        check_output_folder(tmp_path / "f")
    with pytest.raises(InputError, match="is not a folder"):
        check_output_folder(tmp_path / "f" / "sub")
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        with pytest.raises(InputError, match="no write permission"):
            check_output_folder(ro / "out")


def test_no_room_on_the_file_system_is_refused_with_the_size(tmp_path):
    with pytest.raises(InputError, match=r"needs about 8 EiB|needs about 8.*PiB"):
        check_output_folder(tmp_path / "o", expect_bytes=2 ** 63)


def test_format_bytes():
    assert format_bytes(512) == "512 B"
    assert format_bytes(1.5 * 2 ** 30) == "1.5 GiB"
    assert format_bytes(14.5 * 2 ** 40) == "14.5 TiB"


def test_files_and_folder_get_the_umask_permissions(tmp_path, umask_022):
    from fmvmg_sim.record import atomic_write_text
    out = tmp_path / "run"
    with output_folder(out) as tmp:
        atomic_write_text(tmp / "a.json", "{}")  # mkstemp makes 0600 files
        os.close(os.open(tmp / "b.bin", os.O_CREAT | os.O_WRONLY, 0o600))
        (tmp / "sub").mkdir(mode=0o700)
    assert _mode(out) == 0o755 and _mode(out / "sub") == 0o755
    for name in ("a.json", "b.bin", MARKER):
        assert _mode(out / name) == 0o644, name


def test_run_refuses_an_unwritable_output_before_simulating(make_scenario, tmp_path, capsys):
    path = make_scenario(duration_s=0.05)
    (tmp_path / "file").write_text("")
    assert main(["run", str(path), "-o", str(tmp_path / "file"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "not a folder" in err and len(err.strip().splitlines()) == 1


def test_run_refuses_a_record_that_cannot_fit_in_memory(make_scenario, tmp_path, capsys):
    path = make_scenario(duration_s=0.05)
    assert main(["run", str(path), "--set", "scenario.duration_s=1e9", "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "scenario.duration_s x scenario.output_rate_Hz" in err and "TiB" in err
    assert not (tmp_path / "o").exists()


def test_a_second_run_into_the_same_folder_leaves_none_of_the_first_runs_plots(make_scenario, tmp_path, capsys):
    path = make_scenario(duration_s=0.05)
    out = tmp_path / "o"
    assert main(["run", str(path), "-o", str(out), "--no-progress"]) == 0
    assert (out / "startup.png").is_file()
    assert main(["run", str(path), "-o", str(out), "--no-progress", "--no-plots"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "record.csv", "summary.json"]


def test_a_folder_with_files_added_after_its_run_is_not_replaced(tmp_path):
    out = tmp_path / "run"
    with output_folder(out) as tmp:
        (tmp / "record.csv").write_text("1")
    (out / "record-poly-baseline").mkdir()
    (out / "record-poly-baseline" / "compensated.csv").write_text("mine")  # e.g. fmvmg compensate's default
    with pytest.raises(InputError, match="did not write .*compensated.csv"):
        OutputFolder(out)
    assert (out / "record-poly-baseline" / "compensated.csv").read_text() == "mine"
