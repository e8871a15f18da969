"""Base error for mistakes a user can fix (bad file, bad argument, vehicle said no).

The CLI prints these as one line and exits non-zero, without a traceback.
"""


class UserError(Exception):
    """An error caused by input or by a vehicle's answer, reported as one clear line."""
