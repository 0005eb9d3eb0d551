"""fempm.docstrings: the Args: sections the command line's help reads, Sphinx markup made
plain, first sentences outside parentheses."""

import fempm  # noqa: F401  (before dolfinx)
from fempm.docstrings import arguments, first_sentence, plain


def sample(a, b=1):
    """Summary.

    Args:
        a: The first (in m). Continued
            on a second line.
        b: The second, :math:`\\rho g` and :class:`~fempm.stepping.StepOptions`.

    Returns:
        Nothing.
    """


def test_the_args_section_is_read_entry_by_entry():
    assert arguments(sample) == {"a": "The first (in m). Continued on a second line.",
                                 "b": "The second, :math:`\\rho g` and :class:`~fempm.stepping.StepOptions`."}
    assert arguments(lambda: None) == {}


def test_markup_is_made_plain_and_the_first_sentence_taken():
    assert plain(arguments(sample)["b"]) == "The second, \\rho g and StepOptions."
    assert plain("``x`` :mod:`fempm.io`  and\n :func:`f`") == "x fempm.io and f"
    assert first_sentence("The end time (s. below). More.") == "The end time (s. below)."
    assert first_sentence("No period") == "No period"
