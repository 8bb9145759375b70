"""Notes and warnings of a result that name the arguments which address them.

A library result reports a warning as text ("... is at its search bound:
widen its bounds ...") that names what to change, never a command-line
option.  A :class:`Note` is that text (a ``str``, so it prints and serialises
as one) with the names of those arguments in ``hints``; the command line
appends their options when it prints it (``cli.common.note_text``).
"""

from __future__ import annotations

__all__ = ["Note"]


class Note(str):
    """A warning's text with the arguments that address it (``hints``).

    Parameters
    ----------
    text : str
        The warning.
    *hints : str
        Names of the arguments (or keys) that would address it, e.g.
        ``"bounds"``.
    """

    hints: tuple[str, ...]

    def __new__(cls, text: str, *hints: str):
        note = super().__new__(cls, text)
        note.hints = hints
        return note

    def __reduce__(self):
        return (Note, (str(self), *self.hints))
