"""Multi-field contact (:mod:`fempm.stepping.contact`); this path stays for the code that imports it."""

from fempm.stepping.contact import (
    Contact,
    ContactGrid,
    correct,
    shared_cells,
)

__all__ = [
    "Contact",
    "correct",
    "shared_cells",
    "ContactGrid",
]
