"""The hostile-input tests' in-process command runner (a module of its own: under xdist
``import conftest`` may find another folder's conftest)."""

from __future__ import annotations


def cli_exit(argv, capsys):
    """``handle-drake argv`` in-process: (exit code, stderr), argparse's own refusals
    included; never a traceback and never a screenful (the hostile-input tests)."""
    from handle_drake.cli import main

    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own refusals
        code = exit_.code
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err) < 2000, err
    return code, err
