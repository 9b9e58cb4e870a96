"""The exit status of every `graspguide` command, and of the runner processes a demo or a
sweep starts (they read these back)."""

EXIT_OK = 0
EXIT_FAILURE = 1  # a link, disk or run error; or bad data
EXIT_USAGE = 2  # a bad option or input file: the message says what to fix
EXIT_INTERRUPTED = 130  # Ctrl-C, SIGTERM or SIGHUP (128 + SIGINT, as a shell reports it)

__all__ = ["EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_INTERRUPTED"]
