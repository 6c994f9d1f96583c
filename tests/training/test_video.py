"""agri record / agri watch: a playable clip of any policy, headless, from the evaluator's episode."""

import pytest
from PIL import Image

from agri_training.cli import main
from agri_training.evaluation.video import ClipRequest, record


def test_record_writes_a_gif_with_several_frames_of_one_size(tmp_path, capsys):
    out = tmp_path / "clips" / "x.gif"
    argv = ["record", "--env", "agri_envs/GreenhouseNav-v2", "--policy", "harik-apf-gt", "--seed", "0"]
    assert main([*argv, "--out", str(out), "--max-steps", "12"]) == 0
    printed = capsys.readouterr().out
    assert "13 frames of 800x524" in printed
    # a progress line at the start and one at the end (and every 5 s between: a long episode takes minutes)
    assert "recording harik-apf-gt on agri_envs/GreenhouseNav-v2, seed 0 into " in printed
    assert "recording: done, 13 frames in " in printed
    im = Image.open(out)
    assert im.n_frames == 13
    sizes = set()
    for k in range(im.n_frames):
        im.seek(k)
        sizes.add(im.size)
    assert sizes == {(800, 524)}


def test_record_shrinks_and_skips_frames_and_runs_the_chain(tmp_path):
    clip = record(
        ClipRequest("robot_chain_v1", "apoorva-chain", seed=1, out=tmp_path / "c.gif", max_steps=8, every=2, scale=0.5)
    )
    assert clip["frames"] == 5 and clip["size"] == (400, 264) and clip["fps"] == 5.0
    assert Image.open(tmp_path / "c.gif").n_frames == 5


def test_record_mp4(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    import imageio.v2 as iio

    clip = record(ClipRequest("agri_envs/GreenhouseNav-v2", "harik-apf-gt", out=tmp_path / "x.mp4", max_steps=6))
    reader = iio.get_reader(tmp_path / "x.mp4")
    assert reader.count_frames() == clip["frames"] == 7 and reader.get_meta_data()["size"] == (800, 524)


def test_record_refuses_other_files_and_names_the_fix(tmp_path, capsys):
    argv = [
        "record",
        "--env",
        "agri_envs/GreenhouseNav-v2",
        "--policy",
        "harik-apf-gt",
        "--out",
        str(tmp_path / "x.avi"),
    ]
    assert main(argv) == 2
    assert ".gif or .mp4" in capsys.readouterr().err


def test_watch_shows_the_episode_in_a_window(capsys):  # conftest sets SDL's dummy video driver
    argv = ["watch", "--env", "agri_envs/GreenhouseNav-v2", "--policy", "harik-apf-gt", "--max-steps", "3"]
    assert main([*argv, "--env-kwargs", "n_rows=1", "row_length=3"]) == 0
    assert "seed 0: no success after 3 steps" in capsys.readouterr().out
