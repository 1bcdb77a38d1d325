"""The exit codes of every ``glocal-ros`` command."""

EXIT_OK = 0
#: A run, a check or a bench found a failure (a node failed, an object is not learnable, an answer was lost).
EXIT_FAILED = 1
#: Bad input: argparse's own code, and every ``ValueError`` a command raises about its arguments.
EXIT_USAGE = 2
#: The graph made no progress, or a node ended early: the same command resumes the run.
EXIT_STALLED = 3
#: Interrupted (Ctrl-C): what finished is kept, and the same command resumes.
EXIT_INTERRUPTED = 130
