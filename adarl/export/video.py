"""`adarl play`: render a policy's deterministic rollouts offscreen to a video file.

Rendering uses MuJoCo's own offscreen renderer (`mujoco.Renderer`), so no window is needed. The
OpenGL backend is chosen by the `MUJOCO_GL` environment variable, which must be set before MuJoCo
is first imported (`prepare_backend` does it, defaulting to EGL):

* `MUJOCO_GL=egl`   : GPU or Mesa EGL; Debian/Ubuntu package `libegl1` (plus `libgl1-mesa-dri`
                      for software rendering without a GPU).
* `MUJOCO_GL=osmesa`: pure software rendering; Debian/Ubuntu package `libosmesa6`.

`.mp4` files need the `imageio-ffmpeg` package (`pip install 'adarl[video]'`); `.gif` files need
only Pillow (a matplotlib dependency).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from adarl.errors import UsageError
from adarl.files import refuse_special, temp_file

BACKEND_PACKAGES = {
    "egl": "libegl1 (Debian/Ubuntu; add libgl1-mesa-dri to render without a GPU)",
    "osmesa": "libosmesa6 (Debian/Ubuntu)",
    "glfw": "a display (DISPLAY set) and libglfw3",
}
VIDEO_SUFFIXES = (".mp4", ".gif")


def prepare_backend() -> str:
    """Choose the MuJoCo GL backend (EGL unless `MUJOCO_GL` is set) before MuJoCo is imported."""
    backend = os.environ.setdefault("MUJOCO_GL", "egl")
    if backend == "osmesa":
        os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
    elif backend == "egl":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    return backend


def check_video_path(path: Path) -> None:
    """The suffix must be a supported format and its writer installed."""
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise UsageError(
            f"--video {path}: unsupported format; allowed: {', '.join(VIDEO_SUFFIXES)}"
        )
    if path.is_dir():
        raise UsageError(f"--video {path} is a folder; give a file name such as out.mp4")
    if path.suffix.lower() == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise UsageError(
                "writing .mp4 needs imageio-ffmpeg: pip install 'adarl[video]' (or use a .gif path)"
            ) from None


@dataclass
class Episode:
    ret: float
    length: int
    params: dict


class _Camera:
    """A camera that follows the robot's root body from the side."""

    def __init__(self, model):
        import mujoco

        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.cam.trackbodyid = 1 if model.nbody > 1 else 0
        self.cam.distance = max(2.5, 1.0 * float(model.stat.extent))
        self.cam.elevation = -15.0
        self.cam.azimuth = 90.0


def _renderer(model, width: int, height: int):
    import mujoco

    backend = os.environ.get("MUJOCO_GL", "(unset)")
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # the GL stack's errors vary by backend
        package = BACKEND_PACKAGES.get(backend, "an OpenGL backend")
        raise UsageError(
            f"offscreen rendering failed with MUJOCO_GL={backend} ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0] if str(exc) else ''}); it needs {package}, "
            "or set MUJOCO_GL=osmesa (libosmesa6) / MUJOCO_GL=egl (libegl1)"
        ) from exc


def frame_stride(env, fps: int) -> tuple[int, float]:
    """Render every k-th step so that playback at the returned frame rate is real time."""
    base = getattr(env, "unwrapped", env)
    dt = float(getattr(base, "dt", None) or base.model.opt.timestep)
    stride = max(1, round(1.0 / (dt * fps)))
    return stride, 1.0 / (dt * stride)


def render_rollouts(
    policy: Callable[[np.ndarray], np.ndarray],
    env,
    episodes: int,
    seed: int,
    on_frame: Callable[[np.ndarray], None],
    width: int = 640,
    height: int = 480,
    stride: int = 1,
    max_steps: int | None = None,
) -> list[Episode]:
    """Run deterministic episodes of `policy` in `env` (a Gymnasium MuJoCo env; episode k
    resets with `seed + k`) and hand every `stride`-th rendered frame to `on_frame`."""
    base = getattr(env, "unwrapped", env)
    if not hasattr(base, "model") or not hasattr(base, "data"):
        raise UsageError("this task's environment exposes no MuJoCo model to render")
    renderer, model, camera = None, None, None
    results = []
    try:
        for k in range(episodes):
            obs, info = env.reset(seed=seed + k)
            total, length, done = 0.0, 0, False
            while True:
                if base.model is not model:  # the env recompiles its model when dynamics change
                    if renderer is not None:
                        renderer.close()
                    model = base.model
                    renderer, camera = _renderer(model, width, height), _Camera(model)
                if length % stride == 0 or done:
                    renderer.update_scene(base.data, camera=camera.cam)
                    on_frame(renderer.render())
                if done:
                    break
                obs, reward, terminated, truncated, info = env.step(policy(obs))
                total += float(reward)
                length += 1
                done = terminated or truncated or (max_steps is not None and length >= max_steps)
            results.append(Episode(total, length, dict(info.get("dynamics", {}))))
    finally:
        if renderer is not None:
            renderer.close()
    return results


def play(
    policy: Callable[[np.ndarray], np.ndarray],
    task: str,
    dynamics: str,
    video: str | os.PathLike,
    episodes: int = 1,
    seed: int = 0,
    overrides: dict | None = None,
    width: int = 640,
    height: int = 480,
    fps: int = 30,
    max_steps: int | None = None,
) -> list[Episode]:
    """Render `episodes` rollouts of `policy` on `task` under `dynamics` to `video` (.mp4/.gif),
    streamed to a temp file that is renamed at the end, so a failure leaves no partial video."""
    video = Path(video)
    check_video_path(video)
    refuse_special(video, "--video")
    if episodes < 1 or fps < 1 or width < 16 or height < 16:
        raise UsageError("--episodes and --fps must be ≥ 1, --width and --height ≥ 16")
    prepare_backend()
    from adarl.envs import make

    # render_mode keeps the model's textures (floor, sky); we render with our own camera
    env = make(task, dynamics=dynamics, seed=seed, render_mode="rgb_array", **(overrides or {}))
    try:
        check_frame_size(env.unwrapped.model, width, height)
        stride, video_fps = frame_stride(env, fps)
        video.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = temp_file(video.parent, prefix=f".{video.stem}.", suffix=video.suffix)
        os.close(fd)
        try:
            with _writer(tmp, video_fps) as append:
                results = render_rollouts(
                    policy, env, episodes, seed, append, width, height, stride, max_steps
                )
            refuse_special(video, "--video")  # made a FIFO or a device while rendering
            os.replace(tmp, video)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
    finally:
        env.close()
    return results


def check_frame_size(model, width: int, height: int) -> None:
    """A frame must fit the model's offscreen framebuffer (`<visual><global offwidth
    offheight>`, 640 x 480 in Gymnasium's models); else a one-line UsageError naming the flag,
    before any rendering (MuJoCo's own error would be blamed on the GL backend)."""
    limits = model.vis.global_
    for flag, value, limit in (
        ("--width", width, int(limits.offwidth)),
        ("--height", height, int(limits.offheight)),
    ):
        if value > limit:
            raise UsageError(
                f"{flag} {value} is larger than the model's offscreen framebuffer; "
                f"allowed: 16 to {limit}"
            )


@contextlib.contextmanager
def _writer(path: str, fps: float):
    """A frame sink for `path`: ffmpeg (H.264) for .mp4, Pillow for .gif."""
    if path.lower().endswith(".gif"):
        import imageio.v3 as iio

        duration = int(round(1000 / fps))
        with iio.imopen(path, "w", plugin="pillow") as f:
            yield lambda frame: f.write(frame, duration=duration, loop=0)
    else:
        import imageio.v2 as imageio_v2

        with imageio_v2.get_writer(
            path, format="FFMPEG", fps=fps, codec="libx264", quality=7, macro_block_size=8
        ) as w:
            yield w.append_data
