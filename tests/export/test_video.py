"""`adarl play`: offscreen rendering to a video. Rendering runs in a subprocess because MuJoCo
fixes its GL backend (MUJOCO_GL) when first imported; the test is skipped, with the reason,
where no offscreen backend works."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
from synthetic_runs import write_run

from adarl.errors import UsageError
from adarl.export.video import BACKEND_PACKAGES, check_video_path


def test_video_path_checks(tmp_path):
    with pytest.raises(UsageError, match="unsupported format; allowed: .mp4, .gif"):
        check_video_path(tmp_path / "out.avi")
    (tmp_path / "d.gif").mkdir()
    with pytest.raises(UsageError, match="is a folder"):
        check_video_path(tmp_path / "d.gif")
    check_video_path(tmp_path / "out.gif")


def backend_available(backend: str = "egl") -> tuple[bool, str]:
    """Whether MuJoCo can render offscreen with `backend`, checked in a subprocess (the backend is
    fixed at import time). Returns (ok, reason)."""
    code = (
        "import mujoco\n"
        "m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><geom size=\".1\"/></worldbody></mujoco>')\n"
        "r = mujoco.Renderer(m, 16, 16); r.update_scene(mujoco.MjData(m)); r.render(); print('ok')\n"
    )
    env = dict(
        os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend if backend != "glfw" else ""
    )
    try:
        done = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, f"{type(exc).__name__}: {exc}"
    if done.returncode == 0 and "ok" in done.stdout:
        return True, "ok"
    tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
    return (
        False,
        f"MUJOCO_GL={backend} cannot render here ({tail[:200]}); needs {BACKEND_PACKAGES.get(backend)}",
    )


@pytest.fixture(scope="module")
def backend():
    for name in ("egl", "osmesa"):
        ok, reason = backend_available(name)
        if ok:
            return name
    pytest.skip(f"no offscreen OpenGL backend here: {reason}")


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_play_renders_a_video(tmp_path, backend, suffix):
    if suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
        pytest.skip("imageio-ffmpeg is not installed (pip install 'adarl[video]')")
    run = write_run(tmp_path, "r", seeds=(0, 1))
    video = tmp_path / f"out{suffix}"
    env = dict(os.environ, MUJOCO_GL=backend)
    env.pop("PYOPENGL_PLATFORM", None)
    cmd = [sys.executable, "-m", "adarl.cli.main", "play", str(run), "--seed", "1",
           "--dynamics", "nominal", "--hold", "torso_length=0.5", "--video", str(video),
           "--max-episode-steps", "12", "--width", "64", "--height", "48"]  # fmt: skip
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "episode 0: return" in done.stdout and "torso_length=0.5" in done.stdout
    import imageio.v3 as iio

    frames = iio.imread(video, index=None)
    assert frames.shape[0] >= 2 and frames.shape[1:3] == (48, 64)
    assert frames.std() > 0  # not a blank image
    assert [p.name for p in Path(tmp_path).iterdir() if p.name.startswith(".")] == []
    umask = os.umask(0)
    os.umask(umask)
    assert video.stat().st_mode & 0o777 == 0o666 & ~umask  # as any new file, not mkstemp's 0600


def test_play_bad_input_exits_2(tmp_path, monkeypatch, capsys):
    from adarl.cli.main import main

    # `adarl play` sets these for MuJoCo; monkeypatch restores them afterwards
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    run = write_run(tmp_path, "r", seeds=(0,))
    assert main(["play", str(run), "--video", str(tmp_path / "x.avi")]) == 2
    assert "unsupported format" in capsys.readouterr().err
    assert main(["play", str(run), "--seed", "3", "--video", str(tmp_path / "x.gif")]) == 2
    assert "has no seed 3" in capsys.readouterr().err
    assert (
        main(["play", str(run), "--dynamics", "sideways", "--video", str(tmp_path / "x.gif")]) == 2
    )
    assert "unknown dynamics" in capsys.readouterr().err
    assert not (tmp_path / "x.gif").exists()
