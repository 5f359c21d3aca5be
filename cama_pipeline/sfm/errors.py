"""Errors of the SfM stage."""


class SfmError(RuntimeError):
    """A clip (or a set of views) that cannot be reconstructed: too few matches, points or registered images.

    The message names the clip(s) and the images concerned, so a caller can report the clip and skip it.
    """
