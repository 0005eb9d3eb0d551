"""Multi-field contact (:mod:`fempm.stepping.contact`); this path stays for the code that imports it."""

from fempm.stepping.contact import (
    Contact,
    check_options,
    contact_step,
    correct,
    shared_cells,
)

__all__ = [
    "Contact",
    "correct",
    "shared_cells",
    "contact_step",
    "check_options",
]
