"""The exception types a user sees as one line, and the exit code each one gives.

Anything a user can get wrong (a flag, a config field, a task name, a run folder) raises
`UsageError` with a one-line message that names the bad value and what is allowed. The CLI turns
it into `adarl: error: <message>` on stderr and exit code 2. A run that stops for another reason
raises `RunFailed` (a file-system error at run time: exit code 1), `Diverged` (a non-finite
loss, parameter or return: exit code 3) or `Stopped` (SIGTERM or Ctrl-C, after a checkpoint:
128 + the signal's number, as a shell reports a process the signal ended); see
docs/reliability.md.
"""

import dataclasses
import math
import shlex
import signal

#: What a trainer does when a loss, parameter or return stops being finite (`--on-divergence`).
ON_DIVERGENCE = ("stop", "continue")
INT64_MAX = 2**63 - 1
#: `--eval-dynamics ""` (or `eval_dynamics: []`) would skip every evaluation without a word.
EVAL_DYNAMICS_EMPTY = (
    "eval-dynamics is empty (it would skip every evaluation); allowed: one or more dynamics, "
    "comma-separated: nominal, default, paper, ompo, uniform, fixed:NAME=VALUE"
)


class UsageError(ValueError):
    """Bad user input; the message is a single line naming the value and what is allowed."""


class RunFailed(RuntimeError):
    """A run stopped by something other than bad input (a full disk, a lost permission)."""

    exit_code = 1


class Diverged(RunFailed):
    """Training produced a non-finite loss, parameter or return."""

    exit_code = 3


class Stopped(RunFailed):
    """A run that a signal asked to stop (SIGTERM: a cluster's preemption, `kill PID`; SIGINT:
    Ctrl-C) and that stopped at the end of a step with a checkpoint there, so that `--resume`
    goes on from that step exactly. Exit code 128 + the signal's number (143, 130)."""

    def __init__(self, signum: int, step: int, run_dir) -> None:
        super().__init__(
            f"stopped by {signal.Signals(signum).name} at step {step:,} with a checkpoint there; "
            f"resume with: adarl train --resume {shlex.quote(str(run_dir))}"
        )
        self.exit_code = 128 + signum
        self.step = step
        self.run_dir = run_dir

    def resume_from_python(self, *keywords: str) -> "Stopped":
        """This stop, its hint naming the Python call that resumes it (`adarl.train(resume=…)`
        with `keywords` beside it) instead of the CLI command."""
        head = str(self).split("; resume with:")[0]
        call = ", ".join([f"resume={str(self.run_dir)!r}", *keywords])
        self.args = (f"{head}; resume with: adarl.train({call})",)
        return self


#: What a command catches and reports as one line (`failure`); anything else is a bug and shows
#: its traceback.
REPORTED = (UsageError, RunFailed, OSError, KeyboardInterrupt)


def failure(command: str, exc: BaseException) -> tuple[int, str]:
    """The exit code and the one-line message of `command` (e.g. "adarl train") stopped by one
    of the `REPORTED` exceptions: bad input 2, a `RunFailed` its own (1 for the file system, 3 for
    divergence, 128 + the signal for a `Stopped` run), any other file-system error 1, Ctrl-C 130."""
    if isinstance(exc, KeyboardInterrupt):
        return 130, f"{command}: interrupted"
    if isinstance(exc, Stopped):  # asked for, not an error
        return exc.exit_code, f"{command}: {exc}"
    if isinstance(exc, UsageError):
        return 2, f"{command}: error: {exc}"
    if isinstance(exc, RunFailed):
        return exc.exit_code, f"{command}: error: {exc}"
    where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
    return 1, f"{command}: error: {where}{getattr(exc, 'strerror', None) or exc}"


def reason(exc: BaseException) -> str:
    """An exception as one line, `Type: message`, for the parenthesis of a one-line error."""
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def check_choice(kind: str, value: str, allowed) -> str:
    """Return `value` if it is one of `allowed`, else raise a one-line `UsageError`."""
    allowed = list(allowed)
    if value not in allowed:
        raise UsageError(f"unknown {kind} {value!r}; allowed: {', '.join(map(str, allowed))}")
    return value


def check_numbers(config) -> None:
    """Every float field of the dataclass `config` finite, every int field (and int in a tuple)
    within int64, every tuple field a list; else a one-line `UsageError` naming the field."""
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        flag = f.name.replace("_", "-")
        if str(f.type).startswith("tuple") and not isinstance(value, tuple | list):
            raise UsageError(  # `seeds: 0` in a config.yaml
                f"{flag} must be a list (in config.yaml [a, b, ...]; as a flag --{flag} a,b), "
                f"got {value!r}"
            )
        for v in value if isinstance(value, tuple) else (value,):
            if isinstance(v, bool):
                continue
            if isinstance(v, float) and not math.isfinite(v):
                raise UsageError(f"{flag} must be a finite number, got {v}")
            if isinstance(v, int) and not -INT64_MAX - 1 <= v <= INT64_MAX:
                raise UsageError(
                    f"{flag} must fit in a 64-bit integer (at most {INT64_MAX}), got {v}"
                )
