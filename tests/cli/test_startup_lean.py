"""The lean install (`pip install -e . -c constraints.txt`, no extras) runs the quickstart: its
training path, the end-of-training report and summary need none of the extras' packages (Ray,
W&B, MJX, rliable, imageio-ffmpeg, SBX, Stable-Baselines3, torch). Checked by a tiny quickstart
run in a process where those packages cannot be imported."""

import json
import subprocess
import sys

import pytest

#: the import names of the packages only the extras install (pyproject.toml)
EXTRAS_ONLY = (
    "ray",
    "wandb",
    "mujoco.mjx",
    "rliable",
    "imageio_ffmpeg",
    "sbx",
    "stable_baselines3",
    "torch",
    "flax",
)

SCRIPT = """
import json, sys

BLOCKED = {blocked!r}
attempts = []


class NotInstalled:
    '''Every import of an extras-only package fails as if it were not installed.'''

    def find_spec(self, name, path=None, target=None):
        if any(name == b or name.startswith(b + ".") for b in BLOCKED):
            attempts.append(name)
            raise ModuleNotFoundError(f"No module named {{name!r}} (blocked)", name=name)
        return None


sys.meta_path.insert(0, NotInstalled())
from adarl.cli.main import main

code = main({argv!r})
print(json.dumps({{"code": code, "attempts": sorted(set(attempts))}}))
"""

TINY = [  # the quickstart preset at a tiny budget: 2 truncations, 2 evaluations, a checkpoint
    *("--total-steps", "600", "--truncate-every", "200", "--start-steps", "100"),
    *("--update-after", "100", "--update-every", "50", "--warmup-steps", "20"),
    *("--eval-every", "300", "--eval-episodes", "1", "--log-every", "100"),
    *("--checkpoint-every", "300", "--buffer-size", "1000", "--batch-size", "32"),
    *("--max-episode-steps", "100", "--no-progress"),
]


def _run(argv: list[str], cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", SCRIPT.format(blocked=EXTRAS_ONLY, argv=argv)],
        capture_output=True,
        text=True,
        cwd=cwd,
    )


def test_the_blocker_blocks(tmp_path):
    """The check can fail: a command that needs an extra (`--track`, W&B) fails under it."""
    argv = ["train", "--preset", "quickstart", *TINY, "--out", str(tmp_path / "r"), "--track"]
    done = _run(argv, tmp_path)
    assert done.returncode != 0 or json.loads(done.stdout.splitlines()[-1])["code"] != 0
    assert "wandb" in done.stdout + done.stderr


@pytest.mark.slow
def test_the_quickstart_trains_and_reports_without_the_extras(tmp_path):
    run_dir = tmp_path / "quickstart"
    done = _run(["train", "--preset", "quickstart", *TINY, "--out", str(run_dir)], tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["code"] == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert (run_dir / "report" / "index.md").is_file()  # the quickstart's report, figures too
    assert list((run_dir / "report").rglob("*.png"))
    assert "nominal return: " in done.stdout and "report: " in done.stdout
