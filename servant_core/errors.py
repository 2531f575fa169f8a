"""The one error type a user can cause and read."""


class ServantError(Exception):
    """A problem the user can fix, said in one line: what is wrong and what to do.

    The command line prints it without a traceback and exits non-zero; the TUI shows it in the
    log and stays up.
    """
