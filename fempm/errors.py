"""Error norms of particle fields (:mod:`fempm.verification.errors`); this path stays for the code that imports it."""

from fempm.verification.errors import ErrorHistory, l2_error, particle_errors

__all__ = ['l2_error', 'particle_errors', 'ErrorHistory']
