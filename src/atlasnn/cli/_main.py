"""The ``atlasnn`` command line.

    atlasnn systems                      list the built-in Hamiltonian systems
    atlasnn experiments                  list the paper's experiments (built-in configs)
    atlasnn reproduce NAME [--quick] [--seeds K] [--jobs J] [--out DIR]
    atlasnn run CONFIG.toml [...]        a user's own experiment
    atlasnn run|reproduce --resume DIR   continue an interrupted run
    atlasnn run|reproduce --scheduler ADDRESS   the trainings on a Dask cluster ($ATLASNN_SCHEDULER)
    atlasnn report DIR                   re-render tables and figures of a finished run
    atlasnn sweep CONFIG --set KEY=V1,V2 [--set ...] [--seeds K]   a grid of runs and one summary
    atlasnn integrate [CONFIG] [--system NAME] [--T 6.0|20*pi]
                                         reference vs classical integrators, an error table
    atlasnn init NAME.toml [--transfer]  a commented experiment template for your own system
    atlasnn config [--markdown]          every config key: type, default, limits, meaning

Errors caused by input, and file-system errors (a path that cannot be created or written, a full
disk: ``PATH: CAUSE``), are printed as one line; the exit status is 2 when the command failed
before its run started and 1 when it failed mid-run (the run had written its meta.json; its
finished trainings are on disk). SIGINT (Ctrl-C) or SIGTERM during training saves the training
state and exits with status 130, printing the command that resumes the run.
This module holds the commands, their parser and :func:`main`; the checks before a command and
the wording of its failure are in :mod:`atlasnn.cli._errors`.
"""

from __future__ import annotations

import signal
import sys
import threading

from atlasnn.cli._errors import _check_out, _os_error_line, _raise_interrupt, _resume_command, _RunWatch

_MESSAGE_LIMIT = 1000  # characters of an error line; a longer one is cut, with its length
from atlasnn.errors import AtlasError


from atlasnn.cli._parser import build_parser


def quiet_interrupts(unraisable) -> None:
    """``sys.unraisablehook`` for the command line: an interrupt that lands in a finaliser (a
    ``__del__``, a generator being closed) is the one the command is already stopping for, not an
    "Exception ignored" traceback; anything else is reported as Python would."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        return
    sys.__unraisablehook__(unraisable)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):  # no command is a usage error (exit 2), as argparse's own
        parser.print_help(sys.stderr)
        print("atlasnn: error: name a command (atlasnn --help lists them)", file=sys.stderr)
        return 2
    # SIGTERM (kill, a batch system's time limit) is handled like Ctrl-C: the training state is
    # saved and the run can be resumed
    old_unraisable, sys.unraisablehook = sys.unraisablehook, quiet_interrupts
    old_term = None
    if threading.current_thread() is threading.main_thread():
        old = signal.getsignal(signal.SIGTERM)
        if old is not signal.SIG_IGN and old is not None:
            old_term = old
            signal.signal(signal.SIGTERM, _raise_interrupt)
    watch = _RunWatch(args)
    try:
        _check_out(args)
        if getattr(args, "pdf", False):  # figures in PDF too (PNG alone is the default)
            from atlasnn.report import figure_formats

            with figure_formats("png", "pdf"):
                return int(args.func(args) or 0)
        return int(args.func(args) or 0)
    except AtlasError as exc:
        message = " ".join(str(exc).splitlines()) or type(exc).__name__  # one line, always
        if len(message) > _MESSAGE_LIMIT:  # whatever it quotes, a message stays readable
            message = f"{message[:_MESSAGE_LIMIT - 40]}... ({len(message)} characters in all)"
        print(f"atlasnn: error: {message}", file=sys.stderr)
        return watch.status()
    except OSError as exc:  # the file system: a path we cannot create, write or read
        print(f"atlasnn: error: {_os_error_line(exc, getattr(args, 'run_dir', None))}", file=sys.stderr)
        return watch.status()
    except MemoryError:
        print("atlasnn: error: out of memory (MemoryError); lower train.n_points, network.width or --jobs",
              file=sys.stderr)
        return watch.status()
    except KeyboardInterrupt as exc:
        runner = sys.modules.get("atlasnn.experiments._runner")  # loaded if a run was interrupted
        if runner is not None and isinstance(exc, runner.RunInterrupted):
            print(f"atlasnn: interrupted: {exc.finished} of {exc.total} trainings finished; resume with: "
                  f"{_resume_command(args, exc.run_dir)}", file=sys.stderr)
        else:
            print("atlasnn: interrupted", file=sys.stderr)
        return 130
    finally:
        sys.unraisablehook = old_unraisable
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


if __name__ == "__main__":
    sys.exit(main())
