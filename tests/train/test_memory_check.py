"""The memory check of a training run counts every seed's replay buffer and networks (issue 38):
an n-seed run that would fit one seed's buffers but not n seeds' is refused before anything is
written, and the figure it gives is n × one seed's."""

import re

from adarl.cli.main import main
from adarl.train import guards


def _train(tmp_path, seeds: str) -> list[str]:
    return ["train", "--algo", "sac", "--preset", "smoke", "--seeds", seeds, "--buffer-size",
            "20000000", "--total-steps", "200", "--out", str(tmp_path / "run"), "--no-progress"]  # fmt: skip


def test_an_n_seed_run_is_checked_for_n_seeds_buffers(tmp_path, capsys, monkeypatch):
    seen = []
    check = guards.check_memory

    def spy(nbytes, what, lower):
        seen.append(nbytes)
        return check(nbytes, what, lower)

    monkeypatch.setattr(guards, "check_memory", spy)
    monkeypatch.setattr(guards, "machine_memory", lambda: 1)  # nothing fits: the figure only
    assert main(_train(tmp_path, "0")) == 2
    one = seen[-1]
    one_err = capsys.readouterr().err
    one_buffers = float(re.search(r"buffers ([\d.,]+) GiB", one_err).group(1).replace(",", ""))
    assert one > 20_000_000 * 4 * (11 + 3)  # a row holds at least an observation and an action
    # room for one seed (and a half), not for four
    monkeypatch.setattr(guards, "machine_memory", lambda: int(1.5 * one))
    assert main(_train(tmp_path, "0-3")) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "4 seeds" in err, err
    four = seen[-1]
    env = guards.ENV_BYTES
    assert four - 4 * env == 4 * (one - env)  # buffers and networks: four times one seed's
    four_buffers = float(re.search(r"buffers ([\d.,]+) GiB", err).group(1).replace(",", ""))
    assert abs(four_buffers - 4 * one_buffers) <= 4 * 0.05 + 0.05 + 1e-9, (one_err, err)  # rounding
    assert not (tmp_path / "run").exists()  # refused before anything was written
