"""The check every bad-input test makes: `adarl` refuses in one line on stderr with exit code 2."""

from adarl.cli.main import main


def one_line_exit_2(argv, capsys, *needles) -> str:
    """Run `adarl argv`; assert exit 2, one line on stderr holding every needle; return it."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1, err
    for needle in needles:
        assert needle in err, err
    return err
