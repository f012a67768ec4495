"""Atomic writes (leaps_mj.world.files): the old file or the new one, never a partial one."""

import os
import stat

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from leaps_mj.world import files, topdown  # noqa: E402


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("fsync", [False, True])
def test_write_atomic_writes_bytes_readable_by_all_and_leaves_no_temp_file(tmp_path, fsync):
    path = tmp_path / "deep" / "folder" / "state.json"
    files.write_atomic(path, b'{"a": 1}\n', fsync=fsync)
    files.write_atomic(path, b'{"a": 2}\n', fsync=fsync)  # replaces
    assert path.read_bytes() == b'{"a": 2}\n'
    assert _mode(path) == 0o644
    assert os.listdir(path.parent) == ["state.json"]


def test_writer_gets_a_temp_path_in_the_same_folder_with_the_same_suffix(tmp_path):
    seen = []

    def write(tmp):
        seen.append(tmp)
        with open(tmp, "w") as f:
            f.write("x")

    files.write_atomic_with(tmp_path / "clip.mp4", write)
    tmp = seen[0]
    assert os.path.dirname(tmp) == str(tmp_path)
    assert tmp.endswith(".mp4") and os.path.basename(tmp).startswith(".clip.")
    assert not os.path.exists(tmp)
    assert (tmp_path / "clip.mp4").read_text() == "x"


def test_a_failing_writer_leaves_the_old_file_and_no_temp_file(tmp_path):
    path = tmp_path / "model.json"
    files.write_atomic(path, b"old")

    def write(tmp):
        with open(tmp, "wb") as f:
            f.write(b"half")
        raise RuntimeError("killed mid-write")

    with pytest.raises(RuntimeError, match="killed mid-write"):
        files.write_atomic_with(path, write)
    assert path.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["model.json"]


def test_save_figure_writes_a_png_and_closes_the_figure(tmp_path):
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = tmp_path / "plot.png"
    topdown.save_figure(fig, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plt.fignum_exists(fig.number)
    assert os.listdir(tmp_path) == ["plot.png"]
