"""Each exception a command reports becomes one line and its documented exit code
(docs/reliability.md); anything else is not caught."""

import errno

import pytest

from adarl import errors


@pytest.mark.parametrize(
    "exc, code, message",
    [
        (errors.UsageError("bad --seeds 'x'"), 2, "adarl train: error: bad --seeds 'x'"),
        (errors.RunFailed("disk full"), 1, "adarl train: error: disk full"),
        (errors.Diverged("loss is nan"), 3, "adarl train: error: loss is nan"),
        (
            PermissionError(errno.EACCES, "Permission denied", "/r/x.csv"),
            1,
            "adarl train: error: /r/x.csv: Permission denied",
        ),
        (OSError("no space"), 1, "adarl train: error: no space"),
        (KeyboardInterrupt(), 130, "adarl train: interrupted"),
        (
            errors.Stopped(15, 12_345, "runs/my run"),
            143,
            "adarl train: stopped by SIGTERM at step 12,345 with a checkpoint there; "
            "resume with: adarl train --resume 'runs/my run'",
        ),
        (
            errors.Stopped(2, 700, "r"),
            130,
            "adarl train: stopped by SIGINT at step 700 with "
            "a checkpoint there; resume with: adarl train --resume r",
        ),
    ],
)
def test_a_reported_failure_is_one_line_and_its_exit_code(exc, code, message):
    assert isinstance(exc, errors.REPORTED)
    assert errors.failure("adarl train", exc) == (code, message)


def test_a_bug_is_not_reported_as_a_failure():
    assert not isinstance(TypeError("x"), errors.REPORTED)
    assert not isinstance(ZeroDivisionError(), errors.REPORTED)
